// Value types of a stored segment map and the single exception type of the storage library.
//
// A map file is one SQLite database (see docs in map_writer.h for the layout). Every failure
// to read or write one (missing, not SQLite, another application's database, a schema version
// this build does not support, truncated, corrupted, disk full) throws StorageError whose
// message names the file and the problem.
#pragma once

#include <segmatch/core/common/types.h>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace storage {

class StorageError : public std::runtime_error {
 public:
  explicit StorageError(const std::string& message) : std::runtime_error(message) {}
};

// PRAGMA application_id of every segment map: the bytes "SgMp". A database with another id
// belongs to some other program and is refused.
constexpr uint32_t kApplicationId = 0x53674D70u;
// PRAGMA user_version: the schema this build writes, and the oldest one it still reads.
// Schema 2 packs points and ESF losslessly and keeps points in their own table;
// schema 3 stores ESF as u16 integers, sparse (storage/src/packed_blobs.h), the
// rest as schema 2; schema 4 adds the surface layer (map_writer.h), the rest as
// schema 3. Schema 1 to 3 maps are still read; segmatch-mapinfo --upgrade OLD NEW rewrites them
// as schema 4 (without a surface layer: the old file holds no scans to make one from).
constexpr int kSchemaVersion = 4;
constexpr int kOldestReadableSchemaVersion = 1;
// Schema 3 stores each ESF bin as a u16 times 2^e, e in this range (core/esf_quantization.h; the
// range of LOCALIZE_SEGMENTS, docs/protocol.md 5.5: an ESF sums to 1, so 2^0 holds any bin).
constexpr int kMapEsfMinExponent = -64;
constexpr int kMapEsfMaxExponent = 0;

// Keyframe index of a segment whose keyframe is unknown.
constexpr uint32_t kNoKeyframe = 0xFFFFFFFFu;

struct MapMetadata {
  std::string name;
  std::string frame = "map";    // the frame segment centroids, points and poses are in
  std::string created_utc;      // ISO-8601 UTC "YYYY-MM-DDTHH:MM:SSZ"; empty => set at create()
  std::string tool_version;     // version of the program that built the map
  std::string parameters_json;  // every segmentation / description parameter (caller's JSON)
  int eigen_dims = 7;           // must equal kEigenFeatureCount of this build
  int esf_dims = 640;           // must equal kEsfBins of this build
};

// One keyframe of the mapping traversal; T_map_sensor maps sensor points into the map frame.
struct Keyframe {
  uint32_t index = 0;
  double time_s = 0.0;
  Pose3d T_map_sensor = Pose3d::Identity();
};

// The trained segment classifier, stored as opaque bytes (the format string says how to read
// them). The one format this build writes and reads: OpenCV's RTrees saved as YAML.
inline constexpr const char* kClassifierFormatRTreesYaml = "opencv-rtrees-yaml";
struct ClassifierBlob {
  std::string format;
  std::string bytes;
};

// The map's surface layer (MapWriter::set_surfaces): every surface the mapping run saw, thinned
// to leaf_m, in square tiles of tile_m. stored_bytes: the tiles' point BLOBs as stored.
struct SurfaceLayer {
  float leaf_m = 0.f;
  float tile_m = 0.f;
  uint64_t tile_count = 0;
  uint64_t point_count = 0;
  uint64_t stored_bytes = 0;
};

struct MapStats {
  size_t segments = 0;
  size_t points = 0;
  size_t keyframes = 0;
  double trajectory_length_m = 0.0;  // sum of distances between consecutive keyframes
  bool has_classifier = false;
};

}  // namespace storage
}  // namespace segmatch
