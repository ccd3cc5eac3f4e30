// What segmatch-loop writes: the loops as text, a g2o pose graph and a top-down picture.
#pragma once

#include <segmatch/core/loop_closure.h>

#include "loop_eval.h"

#include <string>
#include <vector>

namespace segmatch::loop {

// One line per loop: query_frame match_frame x y z qx qy qz qw inliers confidence, where
// x..qw is T_query_match (translation in metres, unit quaternion). Throws std::runtime_error.
void write_loops_txt(const std::string& path, const std::vector<LoopClosure>& loops);

// Information (inverse covariance) of the edges of the pose graph, upper triangle written
// row by row as g2o expects (translation first, then rotation as quaternion vector part).
struct G2oInformation {
  double loop_translation = 100.0;   // 1 / (0.1 m)^2
  double loop_rotation = 3283.0;     // 1 / (1 deg in rad)^2
  double odometry_translation = 400.0;   // 1 / (0.05 m)^2 per step
  double odometry_rotation = 13131.0;    // 1 / (0.5 deg in rad)^2 per step
};

// VERTEX_SE3:QUAT for each frame (ids = frame indices, odometry poses T_odom_sensor), an
// odometry EDGE_SE3:QUAT between consecutive frames and one loop EDGE_SE3:QUAT
// (id_query id_match, measurement T_query_match) per loop. frames: the frame index of each
// pose. Throws std::runtime_error.
void write_g2o(const std::string& path, const std::vector<size_t>& frames, const Poses& T_odom_sensor,
               const std::vector<LoopClosure>& loops, const G2oInformation& info = {});

// Top-down picture: the odometry trajectory (grey), the processed local clouds (blue dots),
// and the loop edges between the query and match positions (green: true or unscored, red:
// false). correct may be empty (no ground truth). Throws std::runtime_error.
void write_png(const std::string& path, const std::vector<size_t>& frames, const Poses& T_odom_sensor,
               const std::vector<size_t>& processed, const std::vector<LoopClosure>& loops,
               const std::vector<bool>& correct);

// Precision and recall (0..1) against the translation threshold (log scale), one point per
// threshold of the curve. Throws std::runtime_error when it cannot write.
void write_curve_png(const std::string& path, const std::vector<ThresholdPoint>& curve, double rotation_deg);

}  // namespace segmatch::loop
