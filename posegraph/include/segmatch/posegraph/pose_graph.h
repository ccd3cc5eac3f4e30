// Pose-graph optimisation of a trajectory with loop closures (paper IV-D: loops "are fed in a
// pose-graph optimization system ... The result of this optimization is used to update the
// target segment positions"). Nodes are sensor poses T_world_node; odometry edges tie
// consecutive nodes, loop edges tie a query node to the node it recognised. Solved with
// Ceres (Debian's libceres-dev; g2o and GTSAM are not packaged for Debian 12).
//
// Noise model. An odometry edge's standard deviation grows with the distance it covers (an
// odometry's error is a fraction of the distance driven); a loop edge's is fixed at the
// accuracy of a refined SegMatch loop, widened for a loop of lower confidence.
//
// Robustness. Loop edges carry a Cauchy loss on their whitened residual, so a wrong loop that
// the odometry contradicts pulls with a bounded force instead of bending the graph (the same
// idea as dynamic covariance scaling, Agarwal et al. ICRA 2013). Odometry edges are trusted.
// After solving, every loop's weight under the loss is reported; a loop weighted below
// downweighted_weight is one the optimiser did not believe.
//
// Knows no files: segmatch-loop and segmatch-mapbuilder feed it.
#pragma once

#include "segmatch/core/common/types.h"

#include <cstddef>
#include <string>
#include <vector>

namespace segmatch::posegraph {

struct PoseGraphConfig {
  // Odometry edge: translation sigma = max(min, fraction * step length); rotation sigma =
  // max(min, deg_per_m * step length). 2 % and 0.05 deg/m are looser than LiDAR(-inertial)
  // odometry (hku-loop1: 0.5 %, 0.006 deg/m) so that a loop can bend the graph.
  double odometry_sigma_fraction = 0.02;
  double odometry_min_sigma_m = 0.01;
  // Across the step (sideways and up) the translation sigma is this fraction of the
  // along-track one: a vehicle's odometry errs in how far it went far more than sideways.
  // 1: isotropic.
  double odometry_lateral_ratio = 1.0;
  // If > 0: each node's roll and pitch are held to the odometry's within this sigma (an IMU
  // sees gravity, so LiDAR-inertial odometry does not drift in roll and pitch); a height
  // drift is then undone by the steps' translations, not by tilting the trajectory. 0: off.
  double gravity_sigma_deg = 0.0;
  // If > 0: the odometry's yaw-rate, climb and scale biases are estimated per stretch of this many
  // metres (a random walk from one stretch to the next) and removed from its steps. Odometry
  // errors are correlated along a route; white per-step noise alone lets a loop's correction
  // be spread as the smallest change, not as a drift would have made it. 0: off.
  double bias_stretch_m = 100.0;
  double bias_yaw_sigma_deg_per_m = 0.02;  // prior on the first stretch's yaw-rate bias
  double bias_climb_sigma = 0.01;          // ... and its climb bias (metres per metre)
  double bias_yaw_walk_deg_per_m = 0.002;  // change from one stretch to the next
  double bias_climb_walk = 0.001;
  // ... and its scale (a step read this fraction too long; a wheel's radius). Loops back to the
  // same places cannot see it, so without scan edges it stays at its prior, 0.
  double bias_scale_sigma = 0.02;
  double bias_scale_walk = 0.001;
  double odometry_sigma_deg_per_m = 0.05;
  double odometry_min_sigma_deg = 0.05;
  // Loop edge at confidence 1 (refined loops: errors of a few cm and < 1 deg measured); the
  // sigmas are divided by sqrt(confidence) (at least min_loop_confidence).
  double loop_sigma_m = 0.1;
  double loop_sigma_deg = 1.0;
  double min_loop_confidence = 0.1;
  // Scan edge (LiDAR registration of consecutive nodes, scan_edges.h): its sigmas. They carry
  // the robust loss as loops do. Tight in translation (the LiDAR measures metres: this is what
  // fixes an odometry's scale), loose in rotation: a registration's rotation noise, small per
  // step, integrates into height and sideways errors, where an odometry's gyro does better.
  double scan_sigma_m = 0.01;
  double scan_sigma_deg = 1.0;
  // Cauchy loss scale on a loop's whitened residual, in sigmas: a loop off by this many
  // sigmas gets half the weight of a consistent one.
  double robust_scale_sigma = 2.0;
  // Reported as down-weighted: loops whose final weight is below this.
  double downweighted_weight = 0.5;
  int max_iterations = 200;
  void validate() const;  // throws std::invalid_argument naming the field
};

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// T_from_to = T_world_from^-1 * T_world_to, with the square root of its information
// (inverse covariance, residual order: translation xyz, then rotation as 2 * quaternion vector).
struct Edge {
  size_t from = 0, to = 0;  // node indices
  Pose3d T_from_to = Pose3d::Identity();
  Matrix6d sqrt_information = Matrix6d::Identity();
};

// A graph: nodes with their initial poses, odometry edges and loop edges.
struct PoseGraph {
  Poses T_world_node;
  std::vector<Edge> odometry;
  std::vector<Edge> loops;
  std::vector<Edge> scans;  // LiDAR registrations between consecutive nodes (scan_edges.h)
  // The world's up direction in each node's frame as the odometry measured it (the gravity
  // prior's reference; empty: no prior).
  std::vector<Eigen::Vector3d> up_in_node;
};

// sqrt information of a diagonal covariance with these sigmas.
Matrix6d sqrt_information(double sigma_m, double sigma_rad);

// An odometry chain: nodes at the given poses, one edge between each consecutive pair with
// the config's distance-dependent noise.
PoseGraph odometry_graph(const Poses& T_odom_node, const PoseGraphConfig& config);

// The sqrt information of an odometry step T_a_b (the config's distance-dependent sigmas,
// tighter across the step by odometry_lateral_ratio).
Matrix6d odometry_sqrt_information(const Pose3d& T_a_b, const PoseGraphConfig& config);

// A loop edge from node `query` to node `match` with measurement T_query_match and the
// config's loop noise for this confidence.
Edge loop_edge(size_t query, size_t match, const Pose3d& T_query_match, double confidence,
               const PoseGraphConfig& config);

struct LoopReport {
  size_t index = 0;                         // into PoseGraph::loops
  double weight = 1.0;                      // Cauchy weight at the solution (1: fully trusted)
  double residual_m = 0, residual_deg = 0;  // disagreement left at the solution
  bool downweighted = false;                // weight < downweighted_weight
};

struct OptimizationResult {
  Poses T_world_node;             // optimised; node 0 is held fixed
  std::vector<LoopReport> loops;  // one per loop edge, same order
  size_t scans_downweighted = 0;  // scan edges whose weight ended below downweighted_weight
  double initial_cost = 0, final_cost = 0;
  int iterations = 0;
  bool converged = false;
  std::string message;  // Ceres' summary line
  double solve_ms = 0;
};

// Solves the graph from its nodes' poses. Node 0 is fixed (the gauge). Throws
// std::invalid_argument for an edge naming a missing node or a non-finite pose.
OptimizationResult optimize(const PoseGraph& graph, const PoseGraphConfig& config);

// The optimiser run online (as the paper does): odometry nodes arrive one at a time, loops
// as they are detected, and each loop triggers a solve warm-started from the previous
// solution (new nodes follow the odometry from the last optimised node).
class IncrementalPoseGraph {
 public:
  explicit IncrementalPoseGraph(const PoseGraphConfig& config = {});
  // Appends a node at odometry pose T_odom_node; returns its index.
  size_t add_node(const Pose3d& T_odom_node);
  // Adds a loop edge (no solve).
  void add_loop_edge(size_t query, size_t match, const Pose3d& T_query_match, double confidence);
  // Adds a scan edge from node `from` to node `from + 1` (no solve).
  void add_scan_edge(size_t from, const Pose3d& T_from_next);
  // Solves the graph warm-started from the current estimate; returns the solve's result.
  OptimizationResult solve();
  // add_loop_edge, then solve.
  OptimizationResult add_loop(size_t query, size_t match, const Pose3d& T_query_match, double confidence) {
    add_loop_edge(query, match, T_query_match, confidence);
    return solve();
  }
  // Current estimate of every node (odometry before the first loop).
  Poses estimate() const;
  const PoseGraph& graph() const { return graph_; }
  const std::vector<OptimizationResult>& solves() const { return solves_; }

 private:
  PoseGraphConfig config_;
  PoseGraph graph_;  // initial poses = odometry
  Poses solved_;     // estimate of the nodes present at the last solve
  std::vector<OptimizationResult> solves_;
};

// A scan edge from node `from` to `from + 1` with the config's scan noise.
Edge scan_edge(size_t from, const Pose3d& T_from_next, const PoseGraphConfig& config);

// Absolute trajectory error of `estimate` against `truth` (same length): the estimate is
// aligned by its first pose (T_align = truth[0] * estimate[0]^-1, no scale), then the
// position error of every pose. Throws std::invalid_argument on different lengths or empty.
struct TrajectoryError {
  double rmse_m = 0, max_m = 0, final_m = 0;
  double rmse_horizontal_m = 0, rmse_vertical_m = 0;  // the RMSE split into xy and z (world frame)
  size_t max_index = 0;
};
TrajectoryError trajectory_error(const Poses& estimate, const Poses& truth);

}  // namespace segmatch::posegraph
