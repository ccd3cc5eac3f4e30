// Pose-graph optimisation (posegraph/pose_graph.h) on generated trajectories with known
// answers: a drifted odometry around a closed square is corrected by its loops; a wrong loop
// between nearby frames is down-weighted and does not bend the trajectory; the online
// (incremental) optimiser ends where one batch solve does; the trajectory error is exact on
// hand-made cases.
#include "segmatch/posegraph/pose_graph.h"
#include "segmatch/sim/keyframes.h"
#include "support/poses.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace segmatch;
using namespace segmatch::posegraph;

namespace {

Pose3d pose(double x, double y, double z, double yaw_deg) { return test::pose_at(x, y, z, yaw_deg); }

using test::block_loop;

// The odometry of the loop test (tests/loop/loop_closure_test.cpp): 0.2 deg per 100 m too
// much yaw and 2 mm climb per metre; every step 0.3 % too long with scale_error. Loops back
// to the same places cannot observe a scale error (a scaled closed loop still closes), so
// the known-answer tests leave it out.
Poses drifted(const Poses& truth, double scale_error = 0.0) {
  sim::KeyframeConfig drift;
  drift.odom_scale_error = scale_error;
  drift.odom_yaw_drift_deg_per_m = 0.002;
  drift.odom_climb_m_per_m = 0.002;
  drift.odom_heading_walk_deg_per_sqrt_m = drift.odom_pitch_walk_deg_per_sqrt_m = 0;
  return sim::drifted_odometry(truth, drift);
}

// The odometry chain plus true loop edges: every 20 nodes of the second lap to the same place
// on the first.
PoseGraph graph_with_true_loops(const Poses& odom, const Poses& truth, const PoseGraphConfig& c) {
  PoseGraph g = odometry_graph(odom, c);
  const size_t lap = truth.size() / 2;
  for (size_t q = lap + 10; q < truth.size(); q += 20)
    g.loops.push_back(loop_edge(q, q - lap, truth[q].inverse() * truth[q - lap], 0.9, c));
  return g;
}

double max_distance(const Poses& a, const Poses& b) {
  double m = 0;
  for (size_t i = 0; i < a.size(); ++i) m = std::max(m, (a[i].translation() - b[i].translation()).norm());
  return m;
}

}  // namespace

TEST(PoseGraphConfig, RejectsBadValues) {
  PoseGraphConfig c;
  EXPECT_NO_THROW(c.validate());
  c.loop_sigma_m = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.robust_scale_sigma = NAN;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.odometry_min_sigma_deg = -1;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.odometry_lateral_ratio = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.gravity_sigma_deg = -0.1;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

TEST(PoseGraph, EdgeToAMissingNodeIsRefused) {
  PoseGraph g = odometry_graph({Pose3d::Identity(), pose(1, 0, 0, 0)}, {});
  g.loops.push_back(loop_edge(1, 5, Pose3d::Identity(), 1.0, {}));
  EXPECT_THROW(optimize(g, {}), std::invalid_argument);
  g.loops.back().to = 1;  // onto itself
  EXPECT_THROW(optimize(g, {}), std::invalid_argument);
}

TEST(PoseGraph, OdometryAloneIsAFixedPoint) {
  const Poses odom = drifted(block_loop());
  const OptimizationResult r = optimize(odometry_graph(odom, {}), {});
  EXPECT_LT(max_distance(r.T_world_node, odom), 1e-6);
}

TEST(PoseGraph, LoopsCorrectADriftedOdometry) {
  const Poses truth = block_loop();
  const Poses odom = drifted(truth);
  const PoseGraphConfig c;
  PoseGraph g = graph_with_true_loops(odom, truth, c);
  const TrajectoryError before = trajectory_error(odom, truth);
  const OptimizationResult r = optimize(g, c);
  const TrajectoryError after = trajectory_error(r.T_world_node, truth);
  std::printf("[pose graph] %zu loops: ATE RMSE %.3f -> %.3f m, max %.3f -> %.3f m, %d iterations, %.0f ms\n",
              g.loops.size(), before.rmse_m, after.rmse_m, before.max_m, after.max_m, r.iterations, r.solve_ms);
  EXPECT_GT(before.max_m, 1.0) << "the drift must be worth correcting";
  EXPECT_LT(after.rmse_m, 0.25 * before.rmse_m);
  EXPECT_TRUE(r.converged) << r.message;
  for (const LoopReport& l : r.loops) {
    EXPECT_FALSE(l.downweighted) << "true loop " << l.index << ": weight " << l.weight;
    EXPECT_LT(l.residual_m, 0.3);
  }
}

// A wrong loop 3 m off between frames less than 10 m apart, with a real loop's
// information, moves the trajectory by at most 0.5 m and is reported; the true loops still
// correct the drift.
TEST(PoseGraph, AWrongLoopIsDownWeightedAndDoesNotBendTheGraph) {
  const Poses truth = block_loop();
  const Poses odom = drifted(truth);
  const PoseGraphConfig c;
  PoseGraph g = graph_with_true_loops(odom, truth, c);
  const OptimizationResult clean = optimize(g, c);
  const size_t q = 450, m = 442;          // 8 m apart along the second lap's long side
  const Pose3d off = pose(0, 3.0, 0, 0);  // the measurement says 3 m to the side
  g.loops.push_back(loop_edge(q, m, truth[q].inverse() * truth[m] * off, 0.9, c));
  const OptimizationResult r = optimize(g, c);
  const double moved = max_distance(r.T_world_node, clean.T_world_node);
  std::printf("[pose graph] wrong loop: weight %.4f, residual %.2f m; trajectory moved by %.3f m at most\n",
              r.loops.back().weight, r.loops.back().residual_m, moved);
  EXPECT_LE(moved, 0.5);
  EXPECT_TRUE(r.loops.back().downweighted);
  for (size_t i = 0; i + 1 < r.loops.size(); ++i) EXPECT_FALSE(r.loops[i].downweighted) << "true loop " << i;
  EXPECT_LT(trajectory_error(r.T_world_node, truth).rmse_m, 0.25 * trajectory_error(odom, truth).rmse_m);
}

// The same wrong loop without the robust loss would bend the graph: what the loss is for.
TEST(PoseGraph, WithoutTheRobustLossTheWrongLoopWouldBendTheGraph) {
  const Poses truth = block_loop();
  const Poses odom = drifted(truth);
  PoseGraphConfig c;
  PoseGraph g = odometry_graph(odom, c);
  const OptimizationResult clean = optimize(g, c);
  g.loops.push_back(loop_edge(450, 442, truth[450].inverse() * truth[442] * pose(0, 3.0, 0, 0), 0.9, c));
  c.robust_scale_sigma = 1e6;  // Cauchy at a million sigmas: plain least squares
  const double moved = max_distance(optimize(g, c).T_world_node, clean.T_world_node);
  EXPECT_GT(moved, 0.5);
}

TEST(IncrementalPoseGraph, EndsWhereOneBatchSolveDoes) {
  const Poses truth = block_loop();
  const Poses odom = drifted(truth, 0.003);
  const PoseGraphConfig c;
  PoseGraph batch = graph_with_true_loops(odom, truth, c);
  IncrementalPoseGraph online(c);
  size_t next_loop = 0;
  for (size_t i = 0; i < odom.size(); ++i) {
    online.add_node(odom[i]);
    for (; next_loop < batch.loops.size() && batch.loops[next_loop].from == i; ++next_loop) {
      const Edge& e = batch.loops[next_loop];
      online.add_loop(e.from, e.to, e.T_from_to, 0.9);
    }
  }
  ASSERT_EQ(next_loop, batch.loops.size());
  EXPECT_EQ(online.solves().size(), batch.loops.size());
  const OptimizationResult r = optimize(batch, c);
  // Within 3 cm (of 1.8 m corrected): the warm starts and the bias stretches estimated afresh at
  // each solve stop at slightly different points of a flat minimum.
  EXPECT_LT(max_distance(online.estimate(), r.T_world_node), 0.03);
}

TEST(IncrementalPoseGraph, NewNodesFollowTheOdometryFromTheLastSolve) {
  IncrementalPoseGraph g;
  g.add_node(pose(0, 0, 0, 0));
  g.add_node(pose(1, 0, 0, 0));
  g.add_node(pose(2, 0, 0, 0));
  g.add_loop(2, 0, pose(-2, 0, 0, 0), 1.0);  // consistent: nothing moves
  g.add_node(pose(3, 0, 0, 90));
  const Poses e = g.estimate();
  ASSERT_EQ(e.size(), 4u);
  EXPECT_NEAR(e[3].translation().x(), 3.0, 1e-6);
  EXPECT_NEAR(Eigen::AngleAxisd(e[3].linear()).angle(), M_PI / 2, 1e-6);
}

TEST(TrajectoryError, KnownAnswers) {
  const Poses truth = {pose(0, 0, 0, 0), pose(1, 0, 0, 0), pose(2, 0, 0, 0)};
  // The same trajectory in another frame: zero after aligning the first pose.
  Poses moved;
  for (const Pose3d& T : truth) moved.push_back(pose(5, -3, 1, 40) * T);
  EXPECT_NEAR(trajectory_error(moved, truth).rmse_m, 0.0, 1e-12);
  // The last pose 3 m off: RMSE sqrt(9 / 3), max 3 at index 2.
  Poses off = truth;
  off[2].translation().y() += 3.0;
  const TrajectoryError e = trajectory_error(off, truth);
  EXPECT_NEAR(e.rmse_m, std::sqrt(3.0), 1e-12);
  EXPECT_NEAR(e.max_m, 3.0, 1e-12);
  EXPECT_EQ(e.max_index, 2u);
  EXPECT_NEAR(e.final_m, 3.0, 1e-12);
  EXPECT_THROW(trajectory_error(off, {truth[0]}), std::invalid_argument);
}

// Across-track sigma: a step's information is tighter sideways than along it, and the
// along-track row measures along the step.
TEST(PoseGraph, LateralRatioTightensAcrossTheStep) {
  PoseGraphConfig c;
  c.odometry_lateral_ratio = 0.25;
  const Matrix6d s = odometry_sqrt_information(pose(0, 2.0, 0, 0), c);  // a 2 m step along y
  const Eigen::Vector3d along = s.topLeftCorner<3, 3>() * Eigen::Vector3d(0, 1, 0);
  const Eigen::Vector3d across = s.topLeftCorner<3, 3>() * Eigen::Vector3d(1, 0, 0);
  EXPECT_NEAR(along.norm(), 1.0 / 0.04, 1e-9);   // 2 % of 2 m
  EXPECT_NEAR(across.norm(), 1.0 / 0.01, 1e-9);  // a quarter of it
}

// With the gravity prior a height drift is undone by the steps' translations rather than by
// tilting the trajectory: the vertical error left is smaller than without it.
TEST(PoseGraph, GravityPriorKeepsTheTrajectoryLevel) {
  const Poses truth = block_loop();
  sim::KeyframeConfig climb;  // climbs 2 mm per metre, nothing else
  climb.odom_scale_error = 0;
  climb.odom_yaw_drift_deg_per_m = 0;
  climb.odom_climb_m_per_m = 0.002;
  climb.odom_heading_walk_deg_per_sqrt_m = climb.odom_pitch_walk_deg_per_sqrt_m = 0;
  const Poses odom = sim::drifted_odometry(truth, climb);
  auto vertical_rmse = [&](const PoseGraphConfig& c) {
    PoseGraph g = graph_with_true_loops(odom, truth, c);
    return trajectory_error(optimize(g, c).T_world_node, truth).rmse_vertical_m;
  };
  PoseGraphConfig level;
  level.gravity_sigma_deg = 0.1;
  const double without = vertical_rmse({}), with = vertical_rmse(level);
  std::printf("[pose graph] climb drift: vertical RMSE %.3f m without the gravity prior, %.3f m with it\n", without,
              with);
  EXPECT_LT(with, 0.5 * without);
}

// The odometry bias model (bias_stretch_m): a drift that is systematic along the route is
// undone as it was made. Without it, the least-squares correction is the smallest change that
// closes the loops, which is not the drift's shape.
TEST(PoseGraph, BiasModelUndoesASystematicDrift) {
  const Poses truth = block_loop();
  const Poses odom = drifted(truth);
  auto rmse = [&](const PoseGraphConfig& c) {
    PoseGraph g = graph_with_true_loops(odom, truth, c);
    return trajectory_error(optimize(g, c).T_world_node, truth).rmse_m;
  };
  PoseGraphConfig white;
  white.bias_stretch_m = 0;
  const double without = rmse(white), with = rmse({});
  std::printf("[pose graph] systematic drift: RMSE %.3f m with white odometry noise only, %.3f m with the bias model\n",
              without, with);
  EXPECT_LT(with, 0.25 * without);
}
