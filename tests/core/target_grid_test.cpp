// Refinement's nearest-neighbour grid (core/src/detail/target_grid.h) against brute force: the
// nearest point within the bound (ties to the smaller index) and the k nearest, on random
// clouds, on points sitting on cell boundaries, with and without a hint; every point within a
// radius; and NearestCache, which must answer as the grid does for points that keep moving.
#include "detail/target_grid.h"

#include "segmatch/core/detail/random.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

namespace segmatch {
namespace {

using detail::NearestCache;
using detail::TargetGrid;

float sq(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  const float dx = a.x() - b.x(), dy = a.y() - b.y(), dz = a.z() - b.z();
  return dx * dx + dy * dy + dz * dz;  // the grid's own order of operations
}

PointCloud random_cloud(Rng& rng, int n, float side, float cell, bool on_boundaries) {
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    Point p{float(rng.uniform(-side, side)), float(rng.uniform(-side, side)), float(rng.uniform(-1, 1)), 0.f};
    if (on_boundaries && i % 2 == 0)
      p.x = cell * float(rng.uniform_int(-20, 20)), p.z = cell * float(rng.uniform_int(-3, 3));
    cloud.push_back(p);
  }
  return cloud;
}

void expect_grid_equals_brute_force(const PointCloud& target, float cell, Rng& rng, const std::string& what) {
  const TargetGrid grid(target, cell);
  ASSERT_EQ(grid.size(), target.size());
  for (int q = 0; q < 400; ++q) {
    const Eigen::Vector3f p = q % 3 == 0 ? grid.point(uint32_t(rng.uniform_int(0, int(grid.size()) - 1))) +
                                               Eigen::Vector3f(0.f, float(rng.uniform(-0.1, 0.1)), 0.f)
                                         : Eigen::Vector3f(float(rng.uniform(-6, 6)), float(rng.uniform(-6, 6)),
                                                           float(rng.uniform(-1.5, 1.5)));
    const float max2 = q % 2 ? cell * cell : 4.f * cell * cell;
    uint32_t want = detail::FlatHashMap::kMissing;
    float want_d = 0.f;
    for (uint32_t k = 0; k < grid.size(); ++k) {
      const float d = sq(grid.point(k), p);
      if (d <= max2 && (want == detail::FlatHashMap::kMissing || d < want_d)) want = k, want_d = d;
    }
    for (const uint32_t hint : {detail::FlatHashMap::kMissing, uint32_t(rng.uniform_int(0, int(grid.size()) - 1))}) {
      uint32_t got = 0;
      float got_d = 0.f;
      const bool found = grid.nearest(p, max2, hint, &got, &got_d);
      ASSERT_EQ(found, want != detail::FlatHashMap::kMissing) << what << ", query " << q;
      if (!found) continue;
      ASSERT_EQ(got, want) << what << ", query " << q << " (hint " << hint << ")";
      ASSERT_EQ(got_d, want_d) << what << ", query " << q;
    }
    std::vector<uint32_t> knn;
    grid.knn(p, 10, max2, &knn);
    std::vector<float> got_d, want_all;
    for (uint32_t k : knn) got_d.push_back(sq(grid.point(k), p));
    for (uint32_t k = 0; k < grid.size(); ++k)
      if (sq(grid.point(k), p) <= max2) want_all.push_back(sq(grid.point(k), p));
    std::sort(want_all.begin(), want_all.end());
    want_all.resize(std::min<size_t>(want_all.size(), 10));
    ASSERT_EQ(got_d, want_all) << what << ", query " << q << ": the 10 nearest distances";
  }
}

TEST(TargetGridOracle, NearestAndKnnEqualBruteForce) {
  for (uint64_t seed = 1; seed <= 3; ++seed)
    for (bool boundaries : {false, true}) {
      Rng rng(seed);
      const float cell = 0.5f;
      const PointCloud target = random_cloud(rng, 3000, 5.f, cell, boundaries);
      expect_grid_equals_brute_force(target, cell, rng,
                                     "seed " + std::to_string(seed) + (boundaries ? ", on boundaries" : ""));
    }
}

TEST(TargetGridOracle, WithinFindsEveryPointInTheBall) {
  Rng rng(7);
  const PointCloud target = random_cloud(rng, 3000, 5.f, 0.5f, true);
  const TargetGrid grid(target, 0.5f);
  for (int q = 0; q < 300; ++q) {
    const Eigen::Vector3f p(float(rng.uniform(-6, 6)), float(rng.uniform(-6, 6)), float(rng.uniform(-1.5, 1.5)));
    const float r = float(rng.uniform(0.01, 1.2)), r2 = r * r;
    std::vector<uint32_t> got, want;
    grid.within(p, r2, &got);
    for (uint32_t k = 0; k < grid.size(); ++k)
      if (sq(grid.point(k), p) <= r2) want.push_back(k);
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, want) << "query " << q << ", radius " << r;
  }
}

// Source points walking as an ICP's do: steps of centimetres, then millimetres, now and then a
// jump past the cache's margin; some far from every target point. Every answer must be the
// grid's (index and distance bits), and the grid's the brute force's (checked above).
TEST(TargetGridOracle, NearestCacheAnswersAsTheGrid) {
  for (uint64_t seed = 1; seed <= 3; ++seed) {
    Rng rng(seed);
    const PointCloud target = random_cloud(rng, 3000, 5.f, 0.5f, seed == 2);
    const TargetGrid grid(target, 0.5f);
    const size_t n = 200;
    for (const float max_m : {0.5f, 1.5f}) {
      NearestCache cache(grid, n, max_m, 0.05f);
      std::vector<Eigen::Vector3f> p(n);
      for (auto& x : p) x = {float(rng.uniform(-6, 6)), float(rng.uniform(-6, 6)), float(rng.uniform(-1.5, 1.5))};
      size_t hits = 0;
      for (int it = 0; it < 30; ++it) {
        const double step = it < 5 ? 0.03 : it % 10 == 9 ? 0.2 : 0.002;
        for (size_t i = 0; i < n; ++i) {
          p[i] += Eigen::Vector3f(float(rng.uniform(-step, step)), float(rng.uniform(-step, step)),
                                  float(rng.uniform(-step, step)));
          uint32_t want = 0, got = 0;
          float want_d = 0.f, got_d = 0.f;
          const bool found = grid.nearest(p[i], max_m * max_m, detail::FlatHashMap::kMissing, &want, &want_d);
          ASSERT_EQ(cache.nearest(i, p[i], &got, &got_d), found) << "seed " << seed << ", point " << i;
          if (!found) continue;
          ++hits;
          ASSERT_EQ(got, want) << "seed " << seed << ", iteration " << it << ", point " << i;
          ASSERT_EQ(got_d, want_d) << "seed " << seed << ", iteration " << it << ", point " << i;
        }
      }
      EXPECT_GT(hits, n * 10) << "most walkers must have neighbours for the test to say anything";
    }
  }
}

}  // namespace
}  // namespace segmatch
