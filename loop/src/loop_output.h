// What segmatch-loop writes: the loops as text, a g2o pose graph and a top-down picture.
#pragma once

#include <segmatch/core/loop/loop_closure.h>

#include "loop_eval.h"

#include <segmatch/posegraph/pose_graph.h>

#include <string>
#include <vector>

namespace segmatch::loop {

// One line per loop: query_frame match_frame x y z qx qy qz qw inliers confidence, where
// x..qw is T_query_match (translation in metres, unit quaternion). Throws std::runtime_error.
void write_loops_txt(const std::string& path, const std::vector<LoopClosure>& loops);

// VERTEX_SE3:QUAT for each node at T_world_node (ids = frame indices), then every edge of the
// graph (odometry first, then loops: id_query id_match, measurement T_query_match) with its
// information (inverse covariance) as g2o expects: the upper triangle row by row, translation
// first, then rotation as quaternion vector part. FIX on the first node. Throws
// std::runtime_error.
void write_g2o(const std::string& path, const std::vector<size_t>& frames, const Poses& T_world_node,
               const posegraph::PoseGraph& graph);

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
