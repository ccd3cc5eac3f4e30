// Brute-force oracles for the core's fast kernels (nanoflann's practice): Euclidean
// clustering against a plain union-find over every pair of points, the voxel filter against
// a std::map of floor(v / leaf) keys, on random clouds and where fast paths are fragile (points
// exactly on cell boundaries, lattices at exactly the clustering distance, coordinates near
// +-1e6 m); and one segment's ESF descriptor pinned bit for bit.
#include "segmatch/core/description/descriptors.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/core/segmentation/segmenter.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <vector>

namespace segmatch {
namespace {

// ---- Euclidean clustering.

// Components of "closer than d", where close is decided as the segmenter documents it:
// (a - b).squaredNorm() <= d * d in float. Components ordered by their smallest point index,
// points in input order (segment_cloud's contract).
std::vector<std::vector<size_t>> brute_force_clusters(const PointCloud& cloud, float d) {
  std::vector<size_t> parent(cloud.size());
  std::iota(parent.begin(), parent.end(), size_t{0});
  const auto find = [&](size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  const float d2 = d * d;
  for (size_t i = 0; i < cloud.size(); ++i)
    for (size_t j = i + 1; j < cloud.size(); ++j)
      if ((cloud[i].xyz() - cloud[j].xyz()).squaredNorm() <= d2) {
        const size_t a = find(i), b = find(j);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
  std::map<size_t, std::vector<size_t>> by_root;
  for (size_t i = 0; i < cloud.size(); ++i) by_root[find(i)].push_back(i);
  std::vector<std::vector<size_t>> out;
  for (auto& [root, members] : by_root) out.push_back(members);  // roots are the smallest index
  return out;
}

void expect_clusters_equal_brute_force(const PointCloud& cloud, float d, const std::string& what) {
  SegmenterConfig c;
  c.cluster_distance_m = d;
  c.min_points = 1;
  c.max_points = 1 << 30;
  const Segments segments = segment_cloud(cloud, c);
  const std::vector<std::vector<size_t>> expected = brute_force_clusters(cloud, d);
  ASSERT_EQ(segments.size(), expected.size()) << what;
  for (size_t s = 0; s < expected.size(); ++s) {
    ASSERT_EQ(segments[s].points.size(), expected[s].size()) << what << ", segment " << s;
    for (size_t k = 0; k < expected[s].size(); ++k) {
      const Point& got = segments[s].points[k];
      const Point& want = cloud[expected[s][k]];
      ASSERT_TRUE(got.x == want.x && got.y == want.y && got.z == want.z) << what << ", segment " << s << " point " << k;
    }
  }
}

TEST(EuclideanOracle, RandomCloudsEqualBruteForce) {
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    Rng rng(seed);
    const int n = 400 + 300 * int(seed);
    const double side = 1.0 + 0.7 * double(seed);  // from one blob to many small clusters
    PointCloud cloud;
    for (int i = 0; i < n; ++i)
      cloud.push_back(
          {float(rng.uniform(-side, side)), float(rng.uniform(-side, side)), float(rng.uniform(0, 0.5 * side)), 0.f});
    expect_clusters_equal_brute_force(cloud, 0.2f, "seed " + std::to_string(seed));
  }
}

// Points exactly the clustering distance apart, and a hair above and below it, on lattices
// whose points lie on the segmenter's cell boundaries (multiples of the distance), near the
// origin and 10 km away.
TEST(EuclideanOracle, LatticesAtTheDistanceAndOnCellBoundaries) {
  const float d = 0.2f;
  for (float offset : {0.f, -4.f, 10000.f})
    for (float spacing : {d, std::nextafter(d, 0.f), std::nextafter(d, 1.f), 0.5f * d}) {
      PointCloud cloud;
      for (int i = 0; i < 9; ++i)
        for (int j = 0; j < 7; ++j)
          for (int k = 0; k < 3; ++k)
            if ((i * 7 + j * 3 + k) % 5 != 0)  // holes, so that some lattice points stand alone
              cloud.push_back({offset + spacing * float(i), offset + spacing * float(j), spacing * float(k), 0.f});
      expect_clusters_equal_brute_force(cloud, d,
                                        "offset " + std::to_string(offset) + ", spacing " + std::to_string(spacing));
    }
}

// ---- Voxel filter.

struct Voxel {
  int n = 0;
  double x = 0, y = 0, z = 0;
};

// Keys floor(double(v) / leaf) per axis, ordered x, then y, then z (voxel_filter's contract).
std::map<std::array<int64_t, 3>, Voxel> brute_force_voxels(const PointCloud& cloud, double leaf) {
  std::map<std::array<int64_t, 3>, Voxel> voxels;
  for (const Point& p : cloud) {
    const std::array<int64_t, 3> key = {int64_t(std::floor(double(p.x) / leaf)),
                                        int64_t(std::floor(double(p.y) / leaf)),
                                        int64_t(std::floor(double(p.z) / leaf))};
    Voxel& v = voxels[key];
    ++v.n, v.x += p.x, v.y += p.y, v.z += p.z;
  }
  return voxels;
}

void expect_voxels_equal_brute_force(const PointCloud& cloud, float leaf, int min_points, const std::string& what) {
  VoxelGridConfig c;
  c.leaf_m = leaf;
  c.min_points_per_voxel = min_points;
  const PointCloud out = voxel_filter(cloud, c);
  std::vector<std::pair<std::array<int64_t, 3>, Voxel>> expected;
  for (const auto& kv : brute_force_voxels(cloud, leaf))
    if (kv.second.n >= min_points) expected.push_back(kv);
  ASSERT_EQ(out.size(), expected.size()) << what;
  for (size_t k = 0; k < out.size(); ++k) {
    const Voxel& v = expected[k].second;
    const double mean[3] = {v.x / v.n, v.y / v.n, v.z / v.n};
    const float got[3] = {out[k].x, out[k].y, out[k].z};
    for (int a = 0; a < 3; ++a) {
      // The centroid is kept in float: within two float steps of the exact mean.
      const double step =
          std::max(1e-7, double(std::nextafter(std::abs(float(mean[a])), INFINITY) - std::abs(float(mean[a]))));
      ASSERT_NEAR(got[a], mean[a], 2 * step) << what << ", voxel " << k << " axis " << a;
      // ... and in the voxel its points are in (the output order is the voxels' key order).
      ASSERT_EQ(int64_t(std::floor(double(got[a]) / leaf)), expected[k].first[a])
          << what << ", voxel " << k << " axis " << a;
    }
  }
}

// Every point on a voxel boundary k * leaf, or one float step either side of it.
PointCloud boundary_cloud(float leaf, float offset, uint64_t seed) {
  Rng rng(seed);
  PointCloud cloud;
  for (int i = 0; i < 3000; ++i) {
    float v[3];
    for (float& c : v) {
      c = offset + leaf * float(rng.uniform_int(-20, 20));
      const int side = rng.uniform_int(-1, 1);
      if (side != 0) c = std::nextafter(c, side > 0 ? INFINITY : -INFINITY);
    }
    cloud.push_back({v[0], v[1], v[2], 0.f});
  }
  return cloud;
}

TEST(VoxelFilterOracle, PointsOnCellBoundariesEqualBruteForce) {
  for (float leaf : {0.1f, 0.2f, 0.25f})
    for (int min_points : {1, 2})
      expect_voxels_equal_brute_force(boundary_cloud(leaf, 0.f, 3), leaf, min_points,
                                      "leaf " + std::to_string(leaf) + ", min " + std::to_string(min_points));
}

// Near +-1e6 m a float steps by 6.25 cm, coarser than the voxel: whole voxels stay empty.
TEST(VoxelFilterOracle, FarFromTheOriginEqualsBruteForce) {
  for (float offset : {1e6f, -1e6f})
    for (uint64_t seed : {1, 2}) {
      Rng rng(seed);
      PointCloud cloud;
      for (int i = 0; i < 4000; ++i)
        cloud.push_back({offset + float(rng.uniform(-20, 20)), offset + float(rng.uniform(-20, 20)),
                         float(rng.uniform(0, 5)), 0.f});
      expect_voxels_equal_brute_force(cloud, 0.1f, 1, "offset " + std::to_string(offset));
      expect_voxels_equal_brute_force(boundary_cloud(0.1f, offset, seed), 0.1f, 2,
                                      "boundaries at " + std::to_string(offset));
    }
}

// ---- ESF, pinned.

// FNV-1a of the 640 floats' bits.
uint64_t fingerprint(const EsfDescriptor& d) {
  uint64_t h = 1469598103934665603ull;
  for (float v : d) {
    uint32_t b;
    std::memcpy(&b, &v, sizeof b);
    for (int k = 0; k < 4; ++k) h = (h ^ ((b >> (8 * k)) & 0xFF)) * 1099511628211ull;
  }
  return h;
}

// A fixed segment (an L-shaped wall with a post, 0.1 m sampling, no randomness) and the
// default sampling: any change to ESF's sampling, voxel walk or normalisation changes these
// bits. A deliberate change updates the pin and says why in its commit.
TEST(EsfOracle, AFixedSegmentIsPinnedBitForBit) {
  PointCloud cloud;
  for (int i = 0; i < 30; ++i)
    for (int k = 0; k < 20; ++k) {
      cloud.push_back({0.1f * float(i), 0.f, 0.1f * float(k), 0.f});
      if (i < 15) cloud.push_back({0.f, 0.1f * float(i), 0.1f * float(k), 0.f});
    }
  for (int k = 0; k < 30; ++k) cloud.push_back({2.5f, 1.0f, 0.1f * float(k), 0.f});
  const DescriptorConfig defaults;
  const EsfDescriptor d = esf_descriptor(cloud, defaults.esf_samples, defaults.esf_seed);
  std::printf("[esf] fingerprint 0x%016llx, bins 0 %a 100 %a 400 %a\n", (unsigned long long)fingerprint(d), d[0],
              d[100], d[400]);
  EXPECT_EQ(fingerprint(d), 0x614dedea7f58911bull);
}

}  // namespace
}  // namespace segmatch
