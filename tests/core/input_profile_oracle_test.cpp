// The input profile's neighbour searches (a cell grid, neighbour cells pruned by their distance,
// the agreement probe stopping at its first hit) against brute force over every point pair:
// random clouds with points on the cell boundaries, duplicates and non-finite points.
#include "segmatch/core/profile/input_profile.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

using namespace segmatch;

namespace {

// Points in a box of `extent_m`, a third of them snapped to multiples of `cell_m` on one or
// more axes (the cell boundaries), some duplicated, a few not finite.
PointCloud boundary_cloud(uint32_t seed, size_t n, double extent_m, double cell_m) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-extent_m, extent_m);
  PointCloud out;
  for (size_t i = 0; i < n; ++i) {
    double c[3] = {u(rng), u(rng), u(rng)};
    if (i % 3 == 0)
      for (int a = 0; a < 3; ++a)
        if (rng() % 2) c[a] = std::round(c[a] / cell_m) * cell_m;
    out.push_back({float(c[0]), float(c[1]), float(c[2]), 0.f});
    if (i % 50 == 7) out.push_back(out.back());  // a duplicate: distance 0
    if (i % 97 == 11) out.push_back({std::numeric_limits<float>::quiet_NaN(), 1.f, 1.f, 0.f});
  }
  return out;
}

double percentile(std::vector<double> v, double p) {
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

// spacing_p10_m / spacing_p50_m are percentiles of the nearest-neighbour distance (capped at
// 1 m, the point itself excluded) of every point of a scan of fewer than sample_points points.
TEST(InputProfileOracle, SpacingEqualsBruteForceNearestNeighbours) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    for (double extent : {2.0, 6.0}) {
      const PointCloud scan = boundary_cloud(seed, 1500, extent, 1.0);
      std::vector<double> nn;
      for (size_t i = 0; i < scan.size(); ++i) {
        double best = 1.0;
        for (size_t j = 0; j < scan.size(); ++j) {
          if (j == i || !std::isfinite(scan[j].x)) continue;
          best = std::min(best, static_cast<double>((scan[j].xyz() - scan[i].xyz()).norm()));
        }
        nn.push_back(best);
      }
      const InputMeasurements m = measure_input({scan}, {});
      EXPECT_EQ(m.spacing_p10_m, percentile(nn, 0.1)) << "seed " << seed << " extent " << extent;
      EXPECT_EQ(m.spacing_p50_m, percentile(nn, 0.5)) << "seed " << seed << " extent " << extent;
    }
  }
}

// pose_agreement: the fraction of b's points (all of them here: fewer than `sample`) that lie
// within radius_m of a point of a, b moved by the poses.
TEST(InputProfileOracle, PoseAgreementEqualsBruteForce) {
  for (uint32_t seed : {4u, 5u, 6u}) {
    const PointCloud a = boundary_cloud(seed, 1500, 4.0, 0.75), b = boundary_cloud(seed + 100, 1200, 4.0, 0.75);
    Pose3d T_world_b = Pose3d::Identity();
    T_world_b.translation() = Eigen::Vector3d(0.3, -0.2, 0.1);
    const Eigen::Isometry3f T_a_b = T_world_b.cast<float>();
    size_t near = 0;
    for (const Point& q : b) {
      const Eigen::Vector3f p = T_a_b * q.xyz();
      bool hit = false;
      for (const Point& r : a) hit = hit || (std::isfinite(r.x) && static_cast<double>((r.xyz() - p).norm()) < 0.75);
      near += hit;
    }
    EXPECT_EQ(pose_agreement(a, Pose3d::Identity(), b, T_world_b, 0.75),
              static_cast<double>(near) / static_cast<double>(b.size()))
        << "seed " << seed;
  }
}
