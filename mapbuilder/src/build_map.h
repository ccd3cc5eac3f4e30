// What segmatch-mapbuilder does once its arguments are parsed: reads a sequence, builds the
// segment map with core's MapBuilder and writes it atomically with storage's MapWriter.
#pragma once

#include <segmatch/io/sequence.h>

#include <csignal>
#include <cstddef>
#include <optional>
#include <stdexcept>
#include <string>

namespace segmatch::mapbuilder {

// A problem with the command line itself (exit code 2), as opposed to a failure found while
// reading or writing files (exit code 1).
class UsageError : public std::runtime_error {
 public:
  explicit UsageError(const std::string& message) : std::runtime_error(message) {}
};

struct BuildOptions {
  std::string input;            // sequence folder (KITTI or PCD keyframes) or a ROS 2 bag
  io::BagOptions bag;           // which topics of a bag (io/sequence.h)
  std::string output;           // map file
  std::string config_path;      // pipeline config JSON (empty: preset)
  std::string preset;           // pipeline preset (empty or "auto": measured from the input)
  bool print_config = false;    // print the chosen config as JSON and build nothing
  std::string classifier_path;  // empty: the default model if present
  bool no_classifier = false;
  std::string name;                   // map name (empty: the output file's stem)
  std::optional<size_t> first, last;  // scan range, inclusive (default: the whole sequence)
  size_t stride = 1;                  // use every stride-th scan of the range
  double map_every_m = 5.0;           // MapBuilderConfig::map_every_m
  bool force = false;                 // replace an existing map
  std::string odometry_path;          // poses to use instead of the sequence's poses.txt (empty: those)
  bool close_loops = false;           // detect loops and optimise the poses first (loop_poses.h)
  bool scan_edges = false;            // ... with LiDAR registration edges too (posegraph/scan_edges.h)
  // A map with no segments, or fewer than this many per km driven, is refused (nothing is
  // written): the profile's parameters emptied it. 0 refuses only an empty map.
  double min_segments_per_km = 50.0;
};

// Thrown when the segmentation kept too few segments to make a map (exit code 1, nothing written).
class TooFewSegments : public std::runtime_error {
 public:
  explicit TooFewSegments(const std::string& message) : std::runtime_error(message) {}
};

// Builds the map. Returns the process exit code: 0 written, 128 + signal when *stop_signal
// became non-zero during the build (no map written, an existing one kept). Throws UsageError,
// io::IoError, storage::StorageError or std::exception on failures.
int build_map(const BuildOptions& options, const volatile std::sig_atomic_t* stop_signal);

}  // namespace segmatch::mapbuilder
