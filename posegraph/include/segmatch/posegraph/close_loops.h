// Loop closure over a recorded sequence, online as on a vehicle: each scan goes to the
// LoopDetector (paper IV-D) and becomes a node of the pose graph; each detected loop becomes
// a loop edge and re-optimises the graph at once (IncrementalPoseGraph). At the end the
// detector's segment map is moved onto the corrected trajectory and its duplicates merged
// (core/map_correction.h). Used by segmatch-loop and segmatch-mapbuilder --close-loops.
#pragma once

#include "segmatch/core/loop/loop_closure.h"
#include "segmatch/core/mapping/map_correction.h"
#include "segmatch/io/sequence.h"
#include "segmatch/posegraph/pose_graph.h"
#include "segmatch/posegraph/scan_edges.h"

#include <functional>
#include <memory>
#include <optional>
#include <vector>

namespace segmatch::posegraph {

struct CloseLoopsOptions {
  std::vector<size_t> frames;  // frames of the sequence to feed, increasing (node i = frames[i])
  bool optimize = true;        // false: detect only (T_corrected_sensor = odometry)
  PoseGraphConfig graph;
  // Given: each scan is registered onto the previous ones and the step becomes a scan edge
  // (scan_edges.h); the graph is then also solved once at the end, loops or not.
  std::optional<ScanMatchConfig> scan_edges;
  bool verbose = false;  // print what each local cloud did (stderr)
  // Called after each scan with how many of `frames` are done (e.g. a progress bar with ETA;
  // the caller owns its output, so this library prints none).
  std::function<void(size_t done, size_t total)> on_scan;
  // Polled before each scan: true stops the run early (what was fed so far is returned).
  std::function<bool()> should_stop;
};

struct ClosedLoops {
  std::vector<size_t> frames;     // every frame fed
  Poses T_odom_sensor;            // the sequence's poses of those frames (the odometry)
  Poses T_corrected_sensor;       // after the last optimisation (odometry without loops)
  std::vector<size_t> processed;  // frames where a local cloud was matched
  std::vector<double> step_ms;    // detector time of each processed local cloud
  std::vector<LoopClosure> loops;
  // With scan edges: per node, the registration from the previous node (empty for node 0 and
  // where it was rejected), and how many were tried and accepted.
  std::vector<std::optional<Pose3d>> scan_steps;
  size_t scan_edges_tried = 0;
  PoseGraph graph;                               // odometry chain and one edge per loop (initial = odometry)
  std::optional<OptimizationResult> last_solve;  // the final optimisation, if any loop
  std::vector<double> solve_ms;                  // every optimisation, in order (one per loop)
  Segments map_odom;                             // the detector's segment map (odometry frame)
  CorrectedMap map_corrected;                    // the same on the corrected trajectory, duplicates merged
  size_t node_of(size_t frame) const;            // index into frames; throws std::out_of_range
};

// classifier: required when the detector's matcher is kRandomForest.
ClosedLoops close_loops(const io::Sequence& sequence, const LoopDetectorConfig& detector_config,
                        std::shared_ptr<const RandomForestMatcher> classifier, const CloseLoopsOptions& options);

}  // namespace segmatch::posegraph
