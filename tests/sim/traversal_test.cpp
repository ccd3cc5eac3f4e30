#include "segmatch/sim/traversal.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

using namespace segmatch;
using namespace segmatch::sim;

namespace {

World test_world() {
  WorldConfig c;
  c.seed = 11;
  c.blocks_x = 4;
  c.blocks_y = 3;
  return generate_world(c);
}

// Signed lateral offset of a pose from the centre line of the edge it drives (+: left).
double lateral_offset(const World& w, const Traversal& t, size_t i) {
  const auto& e = w.streets.edges[t.edge[i]];
  Eigen::Vector2d a = w.streets.nodes[e.a], b = w.streets.nodes[e.b];
  if (!t.forward[i]) std::swap(a, b);
  const Eigen::Vector2d d = (b - a).normalized(), left(-d.y(), d.x());
  return (t.T_world_lidar[i].translation().head<2>() - a).dot(left);
}

}  // namespace

TEST(Traversal, RouteFollowsStreetsWithoutTurningBack) {
  const World w = test_world();
  Rng rng(3);
  const Route r = plan_route(w.streets, 1500.0, rng);
  double len = 0;
  for (size_t i = 0; i + 1 < r.nodes.size(); ++i) {
    bool adjacent = false;
    for (int e : w.streets.node_edges[r.nodes[i]]) adjacent |= w.streets.other_end(e, r.nodes[i]) == r.nodes[i + 1];
    EXPECT_TRUE(adjacent) << "nodes " << i << " and " << i + 1;
    if (i + 2 < r.nodes.size()) {
      EXPECT_NE(r.nodes[i], r.nodes[i + 2]) << "U-turn at " << i + 1;
    }
    len += (w.streets.nodes[r.nodes[i + 1]] - w.streets.nodes[r.nodes[i]]).norm();
  }
  EXPECT_GE(len, 1500.0);
}

TEST(Traversal, ScansEveryTenthOfASecondAtUrbanSpeedOnTheRightOfTheRoad) {
  const World w = test_world();
  Rng rng(5);
  DriveConfig c;
  const Traversal t = drive(w, plan_route(w.streets, 1000.0, rng), c);
  ASSERT_GT(t.size(), 500u);
  double max_speed = 0, min_speed = 1e9;
  size_t straight = 0;
  for (size_t i = 0; i < t.size(); ++i) {
    EXPECT_NEAR(t.times_s[i], 0.1 * i, 1e-9);
    const auto& T = t.T_world_lidar[i];
    EXPECT_TRUE(T.linear().isUnitary(1e-9));
    EXPECT_GT(T.linear().determinant(), 0.0);
    const Eigen::Vector3d p = T.translation();
    EXPECT_NEAR(p.z() - w.road_height(p.x(), p.y()), c.sensor_height_m, 0.01);
    if (i > 0) {
      // Speed over ground (the path is planned in the plane).
      const double v = (p - t.T_world_lidar[i - 1].translation()).head<2>().norm() / 0.1;
      max_speed = std::max(max_speed, v);
      min_speed = std::min(min_speed, v);
    }
    // Away from corners the vehicle keeps its lane: right of the centre line by half a lane
    // (one lane per direction) or a lane and a half (two).
    const auto& e = w.streets.edges[t.edge[i]];
    const double off = lateral_offset(w, t, i);
    if (std::abs(T.linear().col(0).head<2>().normalized().dot(
            (w.streets.nodes[e.b] - w.streets.nodes[e.a]).normalized())) > 0.9999) {
      ++straight;
      EXPECT_NEAR(-off, (e.lanes_per_direction - 0.5) * w.config.lane_width_m, 0.05) << "frame " << i;
    }
  }
  EXPECT_GT(straight, t.size() / 2);
  // The sensor sits 1.73 m up the tilted vehicle axis, so slope changes add a trace of speed.
  EXPECT_LE(max_speed, c.cruise_speed_mps * 1.001);
  EXPECT_GT(min_speed, 2.0) << "the vehicle never stops";
  EXPECT_GT(max_speed, 0.95 * c.cruise_speed_mps);
}

TEST(Traversal, RevisitDrivesMappedStreetsBothWaysAndNewStreets) {
  const World w = test_world();
  Rng rng(9);
  const Route first = plan_route(w.streets, 1200.0, rng);
  const Route second = plan_revisit_route(w.streets, first, 800.0, rng);
  std::set<std::pair<int, int>> driven;
  for (size_t i = 0; i + 1 < first.nodes.size(); ++i) driven.insert({first.nodes[i], first.nodes[i + 1]});
  double same = 0, opposite = 0, fresh = 0;
  for (size_t i = 0; i + 1 < second.nodes.size(); ++i) {
    const int a = second.nodes[i], b = second.nodes[i + 1];
    const double len = (w.streets.nodes[b] - w.streets.nodes[a]).norm();
    (driven.count({a, b}) ? same : driven.count({b, a}) ? opposite : fresh) += len;
  }
  EXPECT_GT(same, 100.0);
  EXPECT_GT(opposite, 100.0);
  EXPECT_GT(fresh, 50.0);
}

TEST(Traversal, RevisitMatchesFindSameAndOppositeDirectionWithLaneOffset) {
  const World w = test_world();
  Rng rng(9);
  const Route first_route = plan_route(w.streets, 1200.0, rng);
  const Route second_route = plan_revisit_route(w.streets, first_route, 800.0, rng);
  DriveConfig inner;
  inner.inner_lane = true;
  inner.lane_shift_m = 0.6;
  const Traversal first = drive(w, first_route, DriveConfig{});
  const Traversal second = drive(w, second_route, inner);
  const auto matches = match_revisits(first, second);
  ASSERT_EQ(matches.size(), second.size());
  size_t same = 0, opposite = 0, far = 0;
  for (const auto& m : matches) {
    ASSERT_GE(m.reference_frame, 0);
    // Brute-force check of the nearest reference frame.
    const Eigen::Vector2d p = second.T_world_lidar[m.frame].translation().head<2>();
    for (size_t j = 0; j < first.size(); ++j)
      ASSERT_GE((first.T_world_lidar[j].translation().head<2>() - p).norm(), m.distance_m - 1e-9);
    if (m.distance_m < 5.0 && m.heading_diff_deg < 10) {
      ++same;
      EXPECT_GT(m.distance_m, 0.3) << "same-direction revisits drive with a lane offset";
    }
    if (m.distance_m < 8.0 && m.heading_diff_deg > 170) ++opposite;
    far += m.distance_m > 30.0;
  }
  EXPECT_GT(same, 50u);
  EXPECT_GT(opposite, 50u);
  EXPECT_GT(far, 20u) << "some of the revisit drives streets the map never saw";
}
