// Scan edges (posegraph/scan_edges.h): a registration of simulated scans recovers the true
// step where the odometry's is 3 % long, and refuses a scan of another place; in the pose
// graph, loops alone cannot undo an odometry's scale error (a scaled closed loop still
// closes) while scan edges do, and wrong scan edges are down-weighted.
#include "segmatch/posegraph/scan_edges.h"
#include "segmatch/posegraph/pose_graph.h"
#include "segmatch/sim/keyframes.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/raycaster.h"
#include "segmatch/sim/scene.h"
#include "support/poses.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace segmatch;
using namespace segmatch::posegraph;
using namespace segmatch::sim;

namespace {

Pose3d pose(double x, double y, double z, double yaw_deg) { return test::pose_at(x, y, z, yaw_deg); }

// A street: ground, two rows of buildings of different sizes, poles between them.
Scene street() {
  Scene s = {Primitive::triangle({-500, -500, 0}, {500, -500, 0}, {500, 500, 0}, 40, 0.3f),
             Primitive::triangle({-500, -500, 0}, {500, 500, 0}, {-500, 500, 0}, 40, 0.3f)};
  for (int k = -6; k <= 6; ++k) {
    const float x = 14.f * float(k);
    s.push_back(Primitive::box({x, 14.f + float(k % 3), 5.f}, {5.f + float((k + 7) % 3), 3.f, 5.f + float(k % 2)},
                               0.1f * float(k % 2), 50, 0.5f));
    s.push_back(
        Primitive::box({x + 5.f, -15.f, 4.f}, {4.f, 2.5f + float((k + 7) % 2), 4.f}, -0.05f * float(k % 3), 50, 0.5f));
    s.push_back(Primitive::cylinder({x + 7.f, 6.f, 0.f}, 0.15f, 6.f, 80, 0.4f));
  }
  return s;
}

double angle_deg(const Pose3d& T) { return Eigen::AngleAxisd(T.linear()).angle() * 180.0 / M_PI; }

TEST(ScanMatcher, RecoversTheStepWhereTheOdometryIsLong) {
  const RayCaster caster(street());
  const LidarModel lidar = vlp16();
  ScanMatcher matcher;
  const double h = lidar.mount_height_m;
  Poses truth, odom;
  for (int k = 0; k < 6; ++k) {
    truth.push_back(pose(1.5 * k, 0.2 * k, h, 0.5 * k));
    odom.push_back(pose(1.03 * 1.5 * k, 1.03 * 0.2 * k, h, 0.5 * k));  // every step 3 % too long
  }
  for (size_t k = 0; k < truth.size(); ++k) {
    const SimulatedScan scan = simulate_scan(caster, lidar, truth[k], k + 1);
    const std::optional<ScanStep> step = matcher.add(scan.points, odom[k]);
    if (k == 0) {
      EXPECT_FALSE(step.has_value());
      continue;
    }
    ASSERT_TRUE(step.has_value());
    ASSERT_TRUE(step->accepted) << "step " << k << ": " << step->rejected_because << ", fitness " << step->fitness;
    const Pose3d error = (truth[k - 1].inverse() * truth[k]).inverse() * step->T_previous_this;
    EXPECT_LT(error.translation().norm(), 0.01) << "step " << k;  // the odometry is 4.6 cm off
    // Rotation is the weaker part of a sparse scan's registration (0.06-0.12 deg here); the
    // graph weighs it loosely (scan_sigma_deg) and takes it from the odometry.
    EXPECT_LT(angle_deg(error), 0.25) << "step " << k;
  }
}

TEST(ScanMatcher, RefusesAScanOfAnotherPlace) {
  const RayCaster caster(street());
  Scene elsewhere = {Primitive::triangle({-500, -500, 0}, {500, -500, 0}, {500, 500, 0}, 40, 0.3f),
                     Primitive::triangle({-500, -500, 0}, {500, 500, 0}, {-500, 500, 0}, 40, 0.3f),
                     Primitive::box({0, 30, 3}, {20, 1, 3}, 0.7f, 50, 0.5f)};
  const RayCaster other(elsewhere);
  const LidarModel lidar = vlp16();
  ScanMatcher matcher;
  const Pose3d T0 = pose(0, 0, lidar.mount_height_m, 0), T1 = pose(1, 0, lidar.mount_height_m, 0);
  matcher.add(simulate_scan(caster, lidar, T0, 1).points, T0);
  const std::optional<ScanStep> step = matcher.add(simulate_scan(other, lidar, T1, 2).points, T1);
  ASSERT_TRUE(step.has_value());
  EXPECT_FALSE(step->accepted) << "fitness " << step->fitness;
}

TEST(ScanMatchConfig, RejectsBadValues) {
  ScanMatchConfig c;
  c.voxel_m = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.max_range_m = c.min_range_m;
  EXPECT_THROW(ScanMatcher{c}, std::invalid_argument);
  PoseGraphConfig g;
  g.scan_sigma_m = 0;
  EXPECT_THROW(g.validate(), std::invalid_argument);
}

using test::block_loop;

struct ScaleCase {
  Poses truth = block_loop(), odom;
  PoseGraph graph;
  PoseGraphConfig config;
  ScaleCase() {
    KeyframeConfig drift;
    drift.odom_scale_error = 0.01;  // every step 1 % long, nothing else
    drift.odom_yaw_drift_deg_per_m = 0;
    drift.odom_climb_m_per_m = 0;
    drift.odom_heading_walk_deg_per_sqrt_m = drift.odom_pitch_walk_deg_per_sqrt_m = 0;
    odom = drifted_odometry(truth, drift);
    graph = odometry_graph(odom, config);
    const size_t lap = truth.size() / 2;
    for (size_t q = lap + 10; q < truth.size(); q += 20)
      graph.loops.push_back(loop_edge(q, q - lap, truth[q].inverse() * truth[q - lap], 0.9, config));
  }
  void add_true_scan_edges() {
    for (size_t i = 1; i < truth.size(); ++i)
      graph.scans.push_back(scan_edge(i - 1, truth[i - 1].inverse() * truth[i], config));
  }
};

TEST(PoseGraph, ScanEdgesUndoAScaleErrorThatLoopsCannotSee) {
  ScaleCase c;
  const double before = trajectory_error(c.odom, c.truth).rmse_m;
  const double loops_only = trajectory_error(optimize(c.graph, c.config).T_world_node, c.truth).rmse_m;
  c.add_true_scan_edges();
  const OptimizationResult r = optimize(c.graph, c.config);
  const double with_scans = trajectory_error(r.T_world_node, c.truth).rmse_m;
  std::printf("[scan edges] 1 %% scale error: ATE %.3f m, loops only %.3f m, loops and scan edges %.3f m\n", before,
              loops_only, with_scans);
  EXPECT_GT(loops_only, 0.5 * before) << "loops back to the same places should not see the scale";
  EXPECT_LT(with_scans, 0.05);
  EXPECT_EQ(r.scans_downweighted, 0u);
}

TEST(PoseGraph, WrongScanEdgesAreDownWeighted) {
  ScaleCase c;
  c.add_true_scan_edges();
  for (size_t i : {50u, 170u, 333u, 420u, 600u})
    c.graph.scans[i].T_from_to.translation().y() += 1.0;  // an ICP gone wrong
  const OptimizationResult r = optimize(c.graph, c.config);
  const double rmse = trajectory_error(r.T_world_node, c.truth).rmse_m;
  std::printf("[scan edges] 5 wrong scan edges: ATE %.3f m, %zu down-weighted\n", rmse, r.scans_downweighted);
  EXPECT_EQ(r.scans_downweighted, 5u);
  EXPECT_LT(rmse, 0.1);
}

}  // namespace
