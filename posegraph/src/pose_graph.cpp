// Pose-graph optimisation with Ceres: the relative-pose error term of Ceres' own
// pose_graph_3d example (translation difference in the first node's frame, 2 * the vector part
// of the rotation difference), quaternions on Ceres' EigenQuaternionManifold.
#include "segmatch/posegraph/pose_graph.h"

#include "residuals.h"

#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

namespace segmatch::posegraph {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

void require(bool ok, const std::string& field) {
  if (!ok) throw std::invalid_argument("PoseGraphConfig: " + field);
}

// Parameter blocks of the nodes: position and Eigen-ordered quaternion (x, y, z, w).
struct NodeBlocks {
  std::vector<Eigen::Vector3d> p;
  std::vector<Eigen::Quaterniond> q;
  explicit NodeBlocks(const Poses& T) {
    for (const Pose3d& pose : T) {
      if (!pose.matrix().allFinite()) throw std::invalid_argument("pose graph: a node's pose is not finite");
      p.push_back(pose.translation());
      q.push_back(Eigen::Quaterniond(pose.linear()).normalized());
    }
  }
  Poses poses() const {
    Poses out;
    for (size_t i = 0; i < p.size(); ++i) {
      Pose3d T = Pose3d::Identity();
      T.linear() = q[i].normalized().toRotationMatrix();
      T.translation() = p[i];
      out.push_back(T);
    }
    return out;
  }
};

void check_edge(const Edge& e, size_t node_count) {
  if (e.from >= node_count || e.to >= node_count || e.from == e.to)
    throw std::invalid_argument("pose graph: edge " + std::to_string(e.from) + " -> " + std::to_string(e.to) +
                                " names a missing node (" + std::to_string(node_count) + " nodes) or itself");
  if (!e.T_from_to.matrix().allFinite() || !e.sqrt_information.allFinite())
    throw std::invalid_argument("pose graph: edge " + std::to_string(e.from) + " -> " + std::to_string(e.to) +
                                " is not finite");
}

void add_edge(ceres::Problem& problem, NodeBlocks& nodes, const Edge& e, ceres::LossFunction* loss) {
  auto* cost = new ceres::AutoDiffCostFunction<RelativePoseError, 6, 3, 4, 3, 4>(
      new RelativePoseError(e.T_from_to, e.sqrt_information));
  problem.AddResidualBlock(cost, loss, nodes.p[e.from].data(), nodes.q[e.from].coeffs().data(), nodes.p[e.to].data(),
                           nodes.q[e.to].coeffs().data());
}

// Odometry edges with a bias per stretch of bias_stretch_m (in the order of the edges, by the
// distance their steps cover), a prior on the first stretch and a random walk between stretches.
void add_biased_odometry(ceres::Problem& problem, NodeBlocks& nodes, const std::vector<Edge>& odometry,
                         const PoseGraphConfig& c, std::vector<std::array<double, 3>>& biases) {
  double odometer = 0;
  std::vector<size_t> stretch_of;
  for (const Edge& e : odometry) {
    stretch_of.push_back(static_cast<size_t>(odometer / c.bias_stretch_m));
    odometer += e.T_from_to.translation().norm();
  }
  biases.assign(stretch_of.empty() ? 1 : stretch_of.back() + 1, {0.0, 0.0, 0.0});
  for (size_t i = 0; i < odometry.size(); ++i) {
    const Edge& e = odometry[i];
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<BiasedRelativePoseError, 6, 3, 4, 3, 4, 3>(
                                 new BiasedRelativePoseError(e.T_from_to, e.sqrt_information)),
                             nullptr, nodes.p[e.from].data(), nodes.q[e.from].coeffs().data(), nodes.p[e.to].data(),
                             nodes.q[e.to].coeffs().data(), biases[stretch_of[i]].data());
  }
  const Eigen::Vector3d prior(c.bias_yaw_sigma_deg_per_m * kRadPerDeg, c.bias_climb_sigma, c.bias_scale_sigma);
  const Eigen::Vector3d walk(c.bias_yaw_walk_deg_per_m * kRadPerDeg, c.bias_climb_walk, c.bias_scale_walk);
  problem.AddResidualBlock(new ceres::AutoDiffCostFunction<BiasPrior, 3, 3>(new BiasPrior(prior)), nullptr,
                           biases[0].data());
  for (size_t k = 1; k < biases.size(); ++k)
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<BiasStep, 3, 3, 3>(new BiasStep(walk)), nullptr,
                             biases[k - 1].data(), biases[k].data());
}

// The world's up direction in the frame of a node at pose T (the gravity prior's reference).
Eigen::Vector3d up_in(const Pose3d& T) { return T.linear().transpose() * Eigen::Vector3d::UnitZ(); }

LoopReport report_edge(size_t index, const Edge& e, const Poses& T, const PoseGraphConfig& c) {
  const Pose3d estimated = T[e.from].inverse() * T[e.to];
  const Pose3d delta = e.T_from_to.inverse() * estimated;
  const Eigen::Quaterniond dq(delta.linear());
  Eigen::Matrix<double, 6, 1> r;
  r.head<3>() = estimated.translation() - e.T_from_to.translation();
  r.tail<3>() = 2.0 * Eigen::Quaterniond(e.T_from_to.linear() * estimated.linear().transpose()).vec();
  const double s = (e.sqrt_information * r).squaredNorm();
  LoopReport out;
  out.index = index;
  out.weight = 1.0 / (1.0 + s / (c.robust_scale_sigma * c.robust_scale_sigma));  // Cauchy rho'(s)
  out.residual_m = r.head<3>().norm();
  out.residual_deg = Eigen::AngleAxisd(dq).angle() / kRadPerDeg;
  out.downweighted = out.weight < c.downweighted_weight;
  return out;
}

}  // namespace

void PoseGraphConfig::validate() const {
  require(odometry_sigma_fraction >= 0 && std::isfinite(odometry_sigma_fraction),
          "odometry_sigma_fraction must be >= 0");
  require(odometry_min_sigma_m > 0 && std::isfinite(odometry_min_sigma_m), "odometry_min_sigma_m must be > 0");
  require(odometry_sigma_deg_per_m >= 0 && std::isfinite(odometry_sigma_deg_per_m),
          "odometry_sigma_deg_per_m must be >= 0");
  require(odometry_min_sigma_deg > 0 && std::isfinite(odometry_min_sigma_deg), "odometry_min_sigma_deg must be > 0");
  require(loop_sigma_m > 0 && std::isfinite(loop_sigma_m), "loop_sigma_m must be > 0");
  require(loop_sigma_deg > 0 && std::isfinite(loop_sigma_deg), "loop_sigma_deg must be > 0");
  require(scan_sigma_m > 0 && std::isfinite(scan_sigma_m), "scan_sigma_m must be > 0");
  require(scan_sigma_deg > 0 && std::isfinite(scan_sigma_deg), "scan_sigma_deg must be > 0");
  require(min_loop_confidence > 0 && min_loop_confidence <= 1, "min_loop_confidence must be in (0, 1]");
  require(robust_scale_sigma > 0 && std::isfinite(robust_scale_sigma), "robust_scale_sigma must be > 0");
  require(downweighted_weight >= 0 && downweighted_weight <= 1, "downweighted_weight must be in [0, 1]");
  require(max_iterations > 0, "max_iterations must be > 0");
  require(odometry_lateral_ratio > 0 && odometry_lateral_ratio <= 1, "odometry_lateral_ratio must be in (0, 1]");
  require(gravity_sigma_deg >= 0 && std::isfinite(gravity_sigma_deg), "gravity_sigma_deg must be >= 0");
  require(bias_stretch_m >= 0 && std::isfinite(bias_stretch_m), "bias_stretch_m must be >= 0");
  require(bias_yaw_sigma_deg_per_m > 0 && bias_climb_sigma > 0 && bias_scale_sigma > 0 && bias_yaw_walk_deg_per_m > 0 &&
              bias_climb_walk > 0 && bias_scale_walk > 0,
          "the bias sigmas must be > 0");
}

Matrix6d sqrt_information(double sigma_m, double sigma_rad) {
  Matrix6d s = Matrix6d::Zero();
  s.diagonal().head<3>().setConstant(1.0 / sigma_m);
  s.diagonal().tail<3>().setConstant(1.0 / sigma_rad);
  return s;
}

Matrix6d odometry_sqrt_information(const Pose3d& T_a_b, const PoseGraphConfig& c) {
  const double d = T_a_b.translation().norm();
  const double along = std::max(c.odometry_min_sigma_m, c.odometry_sigma_fraction * d);
  const double across = std::max(c.odometry_min_sigma_m, c.odometry_lateral_ratio * along);
  Matrix6d s = sqrt_information(along, std::max(c.odometry_min_sigma_deg, c.odometry_sigma_deg_per_m * d) * kRadPerDeg);
  if (d > 1e-6 && c.odometry_lateral_ratio != 1.0) {
    // Rows: along the step, then two directions across it (the residual is in frame a).
    const Eigen::Vector3d u = T_a_b.translation() / d;
    const Eigen::Vector3d any = std::fabs(u.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
    const Eigen::Vector3d v = u.cross(any).normalized(), w = u.cross(v);
    Eigen::Matrix3d rows;
    rows.row(0) = u.transpose() / along;
    rows.row(1) = v.transpose() / across;
    rows.row(2) = w.transpose() / across;
    s.topLeftCorner<3, 3>() = rows;
  }
  return s;
}

namespace {
// The edge from node `from` at T_from to the next node at T_to.
Edge odometry_edge(size_t from, const Pose3d& T_from, const Pose3d& T_to, const PoseGraphConfig& c) {
  Edge e;
  e.from = from;
  e.to = from + 1;
  e.T_from_to = T_from.inverse() * T_to;
  e.sqrt_information = odometry_sqrt_information(e.T_from_to, c);
  return e;
}
}  // namespace

PoseGraph odometry_graph(const Poses& T_odom_node, const PoseGraphConfig& c) {
  c.validate();
  PoseGraph g;
  g.T_world_node = T_odom_node;
  for (const Pose3d& T : T_odom_node) g.up_in_node.push_back(up_in(T));
  for (size_t i = 1; i < T_odom_node.size(); ++i)
    g.odometry.push_back(odometry_edge(i - 1, T_odom_node[i - 1], T_odom_node[i], c));
  return g;
}

Edge loop_edge(size_t query, size_t match, const Pose3d& T_query_match, double confidence, const PoseGraphConfig& c) {
  const double widen = 1.0 / std::sqrt(std::max(c.min_loop_confidence, std::min(1.0, confidence)));
  Edge e;
  e.from = query;
  e.to = match;
  e.T_from_to = T_query_match;
  e.sqrt_information = sqrt_information(c.loop_sigma_m * widen, c.loop_sigma_deg * widen * kRadPerDeg);
  return e;
}

Edge scan_edge(size_t from, const Pose3d& T_from_next, const PoseGraphConfig& c) {
  Edge e;
  e.from = from;
  e.to = from + 1;
  e.T_from_to = T_from_next;
  e.sqrt_information = sqrt_information(c.scan_sigma_m, c.scan_sigma_deg * kRadPerDeg);
  return e;
}

OptimizationResult optimize(const PoseGraph& graph, const PoseGraphConfig& c) {
  c.validate();
  const auto start = std::chrono::steady_clock::now();
  NodeBlocks nodes(graph.T_world_node);
  OptimizationResult result;
  if (nodes.p.empty()) return result;
  for (const Edge& e : graph.odometry) check_edge(e, nodes.p.size());
  for (const Edge& e : graph.loops) check_edge(e, nodes.p.size());
  for (const Edge& e : graph.scans) check_edge(e, nodes.p.size());
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::EigenQuaternionManifold quaternion;
  for (size_t i = 0; i < nodes.p.size(); ++i) {
    problem.AddParameterBlock(nodes.p[i].data(), 3);
    problem.AddParameterBlock(nodes.q[i].coeffs().data(), 4, &quaternion);
  }
  std::vector<std::array<double, 3>> biases;  // per stretch: yaw rate (rad/m), climb (m/m), scale
  if (c.bias_stretch_m > 0)
    add_biased_odometry(problem, nodes, graph.odometry, c, biases);
  else
    for (const Edge& e : graph.odometry) add_edge(problem, nodes, e, nullptr);
  for (const Edge& e : graph.loops) add_edge(problem, nodes, e, new ceres::CauchyLoss(c.robust_scale_sigma));
  for (const Edge& e : graph.scans) add_edge(problem, nodes, e, new ceres::CauchyLoss(c.robust_scale_sigma));
  if (c.gravity_sigma_deg > 0 && graph.up_in_node.size() == nodes.q.size())
    for (size_t i = 1; i < nodes.q.size(); ++i) {
      problem.AddResidualBlock(new ceres::AutoDiffCostFunction<GravityError, 3, 4>(
                                   new GravityError(graph.up_in_node[i], c.gravity_sigma_deg * kRadPerDeg)),
                               nullptr, nodes.q[i].coeffs().data());
    }
  problem.SetParameterBlockConstant(nodes.p[0].data());
  problem.SetParameterBlockConstant(nodes.q[0].coeffs().data());

  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = c.max_iterations;
  options.num_threads = 1;
  options.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);

  result.T_world_node = nodes.poses();
  for (size_t i = 0; i < graph.loops.size(); ++i)
    result.loops.push_back(report_edge(i, graph.loops[i], result.T_world_node, c));
  for (size_t i = 0; i < graph.scans.size(); ++i)
    result.scans_downweighted += report_edge(i, graph.scans[i], result.T_world_node, c).downweighted;
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size());
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.message = summary.BriefReport();
  result.solve_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

IncrementalPoseGraph::IncrementalPoseGraph(const PoseGraphConfig& config) : config_(config) { config_.validate(); }

size_t IncrementalPoseGraph::add_node(const Pose3d& T_odom_node) {
  if (!T_odom_node.matrix().allFinite()) throw std::invalid_argument("pose graph: a node's pose is not finite");
  graph_.T_world_node.push_back(T_odom_node);
  graph_.up_in_node.push_back(up_in(T_odom_node));
  const size_t n = graph_.T_world_node.size();
  if (n > 1) graph_.odometry.push_back(odometry_edge(n - 2, graph_.T_world_node[n - 2], T_odom_node, config_));
  return n - 1;
}

Poses IncrementalPoseGraph::estimate() const {
  Poses out = solved_;
  const Poses& odom = graph_.T_world_node;
  for (size_t i = out.size(); i < odom.size(); ++i)
    out.push_back(i == 0 ? odom[0] : out.back() * (odom[i - 1].inverse() * odom[i]));
  return out;
}

void IncrementalPoseGraph::add_loop_edge(size_t query, size_t match, const Pose3d& T_query_match, double confidence) {
  graph_.loops.push_back(loop_edge(query, match, T_query_match, confidence, config_));
}

void IncrementalPoseGraph::add_scan_edge(size_t from, const Pose3d& T_from_next) {
  graph_.scans.push_back(scan_edge(from, T_from_next, config_));
}

OptimizationResult IncrementalPoseGraph::solve() {
  PoseGraph warm = graph_;
  warm.T_world_node = estimate();
  OptimizationResult r = optimize(warm, config_);
  solved_ = r.T_world_node;
  solves_.push_back(r);
  return r;
}

TrajectoryError trajectory_error(const Poses& estimate, const Poses& truth) {
  if (estimate.empty() || estimate.size() != truth.size())
    throw std::invalid_argument("trajectory_error: " + std::to_string(estimate.size()) + " estimated poses against " +
                                std::to_string(truth.size()) + " reference poses");
  const Pose3d T_align = truth.front() * estimate.front().inverse();
  TrajectoryError e;
  double sum = 0, sum_z = 0;
  for (size_t i = 0; i < estimate.size(); ++i) {
    const Eigen::Vector3d delta = (T_align * estimate[i]).translation() - truth[i].translation();
    const double d = delta.norm();
    sum += d * d;
    sum_z += delta.z() * delta.z();
    if (d > e.max_m) e.max_m = d, e.max_index = i;
  }
  e.rmse_m = std::sqrt(sum / static_cast<double>(estimate.size()));
  e.rmse_horizontal_m = std::sqrt((sum - sum_z) / static_cast<double>(estimate.size()));
  e.rmse_vertical_m = std::sqrt(sum_z / static_cast<double>(estimate.size()));
  e.final_m = ((T_align * estimate.back()).translation() - truth.back().translation()).norm();
  return e;
}

}  // namespace segmatch::posegraph
