// The BVH ray caster against brute force (one caster per primitive, nearest t, ties to the lower
// index) on random, coincident and clustered scenes, and a large scene.
#include "segmatch/core/detail/random.h"
#include "segmatch/sim/raycaster.h"
#include "segmatch/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace segmatch::sim {
namespace {

constexpr float kPi = 3.14159265358979f;

Primitive random_primitive(Rng& rng, uint32_t label, float extent) {
  const Eigen::Vector3f c(static_cast<float>(rng.uniform(-extent, extent)),
                          static_cast<float>(rng.uniform(-extent, extent)),
                          static_cast<float>(rng.uniform(-extent / 4, extent / 4)));
  auto u = [&](double lo, double hi) { return static_cast<float>(rng.uniform(lo, hi)); };
  const float refl = u(0.0, 1.0);
  switch (rng.uniform_int(0, 4)) {
    case 0: return Primitive::box(c, {u(0.1, 3), u(0.1, 3), u(0.1, 3)}, u(-kPi, kPi), label, refl);
    case 1:  // long thin box (wall, rail)
      return Primitive::box(c, {u(5, 30), u(0.05, 0.3), u(0.5, 4)}, u(-kPi, kPi), label, refl);
    case 2: return Primitive::cylinder(c, u(0.05, 1.5), u(0.5, 10), label, refl);
    case 3: return Primitive::ellipsoid(c, {u(0.2, 4), u(0.2, 4), u(0.2, 4)}, label, refl);
    default: {
      const Eigen::Vector3f e1(u(-5, 5), u(-5, 5), u(-2, 2)), e2(u(-5, 5), u(-5, 5), u(-2, 2));
      return Primitive::triangle(c, c + e1, c + e2, label, refl);
    }
  }
}

// Brute force: one caster per primitive, nearest t, ties to the lower index.
struct BruteForce {
  explicit BruteForce(const Scene& scene) {
    for (const Primitive& p : scene) singles.emplace_back(Scene{p});
  }
  bool cast(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float tmin, float tmax, RayHit* out) const {
    bool any = false;
    for (const RayCaster& c : singles) {
      RayHit h;
      if (c.cast(o, d, tmin, tmax, &h) && (!any || h.range_m < out->range_m)) {
        *out = h;
        any = true;
      }
    }
    return any;
  }
  std::vector<RayCaster> singles;
};

void compare_with_brute_force(const Scene& scene, uint64_t seed, int rays, float extent) {
  const RayCaster bvh(scene);
  const BruteForce brute(scene);
  Rng rng(seed);
  int hits = 0;
  for (int i = 0; i < rays; ++i) {
    const Eigen::Vector3f o(static_cast<float>(rng.uniform(-extent, extent)),
                            static_cast<float>(rng.uniform(-extent, extent)),
                            static_cast<float>(rng.uniform(-extent / 4, extent / 4)));
    Eigen::Vector3f d(static_cast<float>(rng.normal()), static_cast<float>(rng.normal()),
                      static_cast<float>(rng.normal() * 0.5));
    if (i % 2 == 0) {  // aim at a primitive's reference point, jittered
      const Primitive& p = scene[rng.index(scene.size())];
      d = p.a +
          Eigen::Vector3f(static_cast<float>(rng.normal()), static_cast<float>(rng.normal()),
                          static_cast<float>(rng.normal())) *
              0.5f -
          o;
    }
    if (i % 10 == 0) d = Eigen::Vector3f(d.x(), 0.0f, 0.0f);  // axis-parallel rays too
    if (i % 10 == 1) d = Eigen::Vector3f(0.0f, 0.0f, d.z() < 0 ? -1.0f : 1.0f);
    d.normalize();
    const float tmin = (i % 3 == 0) ? 0.0f : static_cast<float>(rng.uniform(0.0, 5.0));
    const float tmax = static_cast<float>(rng.uniform(10.0, 4.0 * extent));
    RayHit a, b;
    const bool ha = bvh.cast(o, d, tmin, tmax, &a);
    const bool hb = brute.cast(o, d, tmin, tmax, &b);
    ASSERT_EQ(ha, hb) << "ray " << i;
    if (!ha) continue;
    ++hits;
    ASSERT_NEAR(a.range_m, b.range_m, 1e-4f) << "ray " << i;
    ASSERT_EQ(a.label, b.label) << "ray " << i;
    ASSERT_FLOAT_EQ(a.reflectivity, b.reflectivity);
    ASSERT_NEAR((a.normal - b.normal).norm(), 0.0f, 1e-5f);
    ASSERT_NEAR(a.normal.norm(), 1.0f, 1e-5f);
    ASSERT_LE(a.normal.dot(d), 1e-6f);
    ASSERT_GE(a.range_m, tmin);
    ASSERT_LE(a.range_m, tmax);
  }
  EXPECT_GT(hits, rays / 10) << "the test scene should be hit often";
  EXPECT_LT(hits, rays) << "the test scene should be missed sometimes";
}

TEST(RayCasterBvh, MatchesBruteForceOnRandomMixedScene) {
  Rng rng(1234);
  Scene scene;
  for (uint32_t i = 0; i < 2000; ++i) scene.push_back(random_primitive(rng, 1000 + i, 60.0f));
  const RayCaster caster(scene);
  EXPECT_EQ(caster.primitive_count(), scene.size());
  compare_with_brute_force(scene, 99, 4000, 60.0f);
}

TEST(RayCasterBvh, MatchesBruteForceOnCoincidentAndClusteredPrimitives) {
  // Identical primitives (all centroids equal: median-split fallback, exact ties resolved
  // to the lower index) plus an exponentially spread chain that provokes a deep tree.
  Scene scene;
  for (uint32_t i = 0; i < 100; ++i) {
    scene.push_back(Primitive::box({0, 0, 0}, {1, 1, 1}, 0.0f, 500 + i, 0.5f));
  }
  for (uint32_t i = 0; i < 300; ++i) {
    const float x = 2.0f + std::pow(1.015f, static_cast<float>(i));  // 3 .. 88 m
    scene.push_back(Primitive::ellipsoid({x, 0.5f, 0}, {0.3f, 0.3f, 0.3f}, 1000 + i, 0.5f));
  }
  RayHit hit;
  const RayCaster caster(scene);
  ASSERT_TRUE(caster.cast({-10, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_EQ(hit.label, 500u);  // tie among 100 identical boxes -> lowest index
  compare_with_brute_force(scene, 7, 1500, 20.0f);
}

TEST(RayCasterBvh, LargeSceneBuildsAndCasts) {
  Rng rng(5);
  Scene scene;
  for (uint32_t i = 0; i < 50000; ++i) scene.push_back(random_primitive(rng, i, 500.0f));
  const RayCaster caster(scene);
  EXPECT_EQ(caster.primitive_count(), scene.size());
  // Spot check against brute force over the primitives near the ray segment (every
  // primitive's extent is < 35 m from its reference point).
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const Eigen::Vector3f o(static_cast<float>(rng.uniform(-400, 400)), static_cast<float>(rng.uniform(-400, 400)),
                            0.0f);
    const Eigen::Vector3f d = Eigen::Vector3f(static_cast<float>(rng.normal()), static_cast<float>(rng.normal()),
                                              static_cast<float>(rng.normal() * 0.2))
                                  .normalized();
    RayHit a;
    const bool ha = caster.cast(o, d, 0.5f, 120.0f, &a);
    bool hb = false;
    float best = 0.0f;
    uint32_t best_label = 0;
    for (const Primitive& p : scene) {
      const float s = std::min(120.0f, std::max(0.0f, (p.a - o).dot(d)));
      if ((o + s * d - p.a).norm() > 40.0f) continue;
      RayHit h;
      if (RayCaster(Scene{p}).cast(o, d, 0.5f, 120.0f, &h) && (!hb || h.range_m < best)) {
        hb = true;
        best = h.range_m;
        best_label = h.label;
      }
    }
    ASSERT_EQ(ha, hb) << "ray " << i;
    if (ha) {
      ++hits;
      EXPECT_NEAR(a.range_m, best, 1e-4f);
      EXPECT_EQ(a.label, best_label);
    }
  }
  EXPECT_GT(hits, 10);
}

TEST(RayCasterBvh, MoveKeepsTheStructure) {
  RayCaster a(Scene{Primitive::box({5, 0, 0}, {1, 1, 1}, 0.0f, 9, 0.5f)});
  RayCaster b(std::move(a));
  RayHit hit;
  ASSERT_TRUE(b.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 10.0f, &hit));
  EXPECT_EQ(hit.label, 9u);
  RayCaster c(Scene{});
  c = std::move(b);
  EXPECT_EQ(c.primitive_count(), 1u);
  EXPECT_TRUE(c.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 10.0f, nullptr));
}

}  // namespace
}  // namespace segmatch::sim
