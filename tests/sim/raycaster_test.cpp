// Tests of the BVH ray caster: exact hits and normals per primitive type, range limits and
// robustness against degenerate input (raycaster_bvh_test.cpp: the BVH against brute force).
#include "segmatch/sim/raycaster.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace segmatch::sim {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kTol = 1e-4f;

Eigen::Vector3f unit(float x, float y, float z) { return Eigen::Vector3f(x, y, z).normalized(); }

// Casts and expects a hit; returns it.
RayHit expect_hit(const RayCaster& caster, const Eigen::Vector3f& origin, const Eigen::Vector3f& dir,
                  float min_range = 0.0f, float max_range = 1000.0f) {
  RayHit hit;
  EXPECT_TRUE(caster.cast(origin, dir, min_range, max_range, &hit))
      << "origin " << origin.transpose() << " dir " << dir.transpose();
  return hit;
}

void expect_normal(const RayHit& hit, const Eigen::Vector3f& expected) {
  EXPECT_NEAR(hit.normal.norm(), 1.0f, 1e-5f);
  EXPECT_NEAR(hit.normal.x(), expected.x(), kTol) << hit.normal.transpose();
  EXPECT_NEAR(hit.normal.y(), expected.y(), kTol) << hit.normal.transpose();
  EXPECT_NEAR(hit.normal.z(), expected.z(), kTol) << hit.normal.transpose();
}

// ---------------------------------------------------------------------------------------
// Primitives, analytically.

TEST(RayCasterPrimitives, FactoriesStoreTheirArguments) {
  const Primitive b = Primitive::box({1, 2, 3}, {4, 5, 6}, 0.5f, 7, 0.25f);
  EXPECT_EQ(b.shape, Shape::kBox);
  EXPECT_EQ(b.a, Eigen::Vector3f(1, 2, 3));
  EXPECT_EQ(b.b, Eigen::Vector3f(4, 5, 6));
  EXPECT_FLOAT_EQ(b.yaw, 0.5f);
  EXPECT_EQ(b.label, 7u);
  EXPECT_FLOAT_EQ(b.reflectivity, 0.25f);
  const Primitive c = Primitive::cylinder({1, 2, 3}, 0.5f, 4.0f, 8, 0.5f);
  EXPECT_EQ(c.shape, Shape::kCylinder);
  EXPECT_FLOAT_EQ(c.b.x(), 0.5f);
  EXPECT_FLOAT_EQ(c.b.z(), 4.0f);
  const Primitive e = Primitive::ellipsoid({1, 2, 3}, {3, 2, 1}, 9, 0.5f);
  EXPECT_EQ(e.shape, Shape::kEllipsoid);
  EXPECT_EQ(e.b, Eigen::Vector3f(3, 2, 1));
  const Primitive t = Primitive::triangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0}, 10, 0.5f);
  EXPECT_EQ(t.shape, Shape::kTriangle);
  EXPECT_EQ(t.c, Eigen::Vector3f(0, 1, 0));
}

TEST(RayCasterPrimitives, AxisAlignedBox) {
  const RayCaster caster(Scene{Primitive::box({10, 0, 0}, {1, 2, 3}, 0.0f, 42, 0.7f)});
  RayHit hit = expect_hit(caster, {0, 0, 0}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 9.0f, kTol);
  EXPECT_EQ(hit.label, 42u);
  EXPECT_FLOAT_EQ(hit.reflectivity, 0.7f);
  expect_normal(hit, {-1, 0, 0});
  // From above onto the top face.
  hit = expect_hit(caster, {10.5f, 1.0f, 10.0f}, {0, 0, -1});
  EXPECT_NEAR(hit.range_m, 7.0f, kTol);
  expect_normal(hit, {0, 0, 1});
  // Oblique onto the -y face: from (10, -10, 0) towards (10.5, -2, 1).
  const Eigen::Vector3f o(10, -10, 0);
  const Eigen::Vector3f d = unit(0.5f, 8.0f, 1.0f);
  hit = expect_hit(caster, o, d);
  EXPECT_NEAR(hit.range_m, Eigen::Vector3f(0.5f, 8.0f, 1.0f).norm(), kTol);
  expect_normal(hit, {0, -1, 0});
  // Misses: beside, above, pointing away.
  EXPECT_FALSE(caster.cast({0, 2.5f, 0}, {1, 0, 0}, 0.0f, 1000.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 3.5f}, {1, 0, 0}, 0.0f, 1000.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 0}, {-1, 0, 0}, 0.0f, 1000.0f, &hit));
}

TEST(RayCasterPrimitives, BoxRotatedByYaw30Degrees) {
  const float yaw = 30.0f * kPi / 180.0f;
  const float c = std::cos(yaw), s = std::sin(yaw);
  const RayCaster caster(Scene{Primitive::box({10, 0, 0}, {1, 1, 1}, yaw, 1, 0.5f)});
  // Along +x through the centre: enters the local -x face, n.(p - c) = -1 with n = (c, s, 0).
  RayHit hit = expect_hit(caster, {0, 0, 0}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 10.0f - 1.0f / c, kTol);
  expect_normal(hit, {-c, -s, 0});
  // Along +y through the centre: enters the local -y face, local y axis (-s, c, 0).
  hit = expect_hit(caster, {10, -10, 0}, {0, 1, 0});
  EXPECT_NEAR(hit.range_m, 10.0f - 1.0f / c, kTol);
  expect_normal(hit, {s, -c, 0});
  // Straight down onto the top face at local (0.9, 0.9): inside the rotated box but
  // outside the unrotated one.
  const Eigen::Vector3f top(10 + 0.9f * (c - s), 0.9f * (s + c), 10);
  hit = expect_hit(caster, top, {0, 0, -1});
  EXPECT_NEAR(hit.range_m, 9.0f, kTol);
  expect_normal(hit, {0, 0, 1});
  // Inside the world AABB (x up to 10 + c + s, y up to s + c) but outside the box: miss.
  EXPECT_FALSE(caster.cast({11.2f, 1.2f, 10}, {0, 0, -1}, 0.0f, 100.0f, &hit));
  // Inside the unrotated box but outside the rotated one (local x' = c + s > 1): miss.
  const Eigen::Vector3f q(11.0f - 0.02f, 0.98f, 10);  // local x' = (c + s) * 0.98 > 1
  EXPECT_FALSE(caster.cast(q, {0, 0, -1}, 0.0f, 100.0f, &hit));
}

TEST(RayCasterPrimitives, CylinderSideAndCaps) {
  const RayCaster caster(Scene{Primitive::cylinder({5, 0, 0}, 0.5f, 2.0f, 3, 0.5f)});
  // Side, through the axis.
  RayHit hit = expect_hit(caster, {0, 0, 1}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 4.5f, kTol);
  expect_normal(hit, {-1, 0, 0});
  // Side, off the axis by 0.3: x = 5 - sqrt(0.25 - 0.09) = 4.6, normal (-0.4, 0.3)/0.5.
  hit = expect_hit(caster, {0, 0.3f, 1}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 4.6f, kTol);
  expect_normal(hit, {-0.8f, 0.6f, 0});
  // Top cap from above, bottom cap from below.
  hit = expect_hit(caster, {5.2f, 0.1f, 10}, {0, 0, -1});
  EXPECT_NEAR(hit.range_m, 8.0f, kTol);
  expect_normal(hit, {0, 0, 1});
  hit = expect_hit(caster, {4.9f, -0.2f, -3}, {0, 0, 1});
  EXPECT_NEAR(hit.range_m, 3.0f, kTol);
  expect_normal(hit, {0, 0, -1});
  // Oblique onto the top cap: from (4, 0, 4) towards (5.2, 0, 2).
  const Eigen::Vector3f to(1.2f, 0.0f, -2.0f);
  hit = expect_hit(caster, {4, 0, 4}, to.normalized());
  EXPECT_NEAR(hit.range_m, to.norm(), kTol);
  expect_normal(hit, {0, 0, 1});
  // Misses: above the top, below the base, beside.
  EXPECT_FALSE(caster.cast({0, 0, 2.1f}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, -0.1f}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0.51f, 1}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({5.6f, 0, 10}, {0, 0, -1}, 0.0f, 100.0f, &hit));
}

TEST(RayCasterPrimitives, EllipsoidOnAndOffAxis) {
  const RayCaster caster(Scene{Primitive::ellipsoid({10, 0, 0}, {2, 1, 0.5f}, 4, 0.5f)});
  RayHit hit = expect_hit(caster, {0, 0, 0}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 8.0f, kTol);
  expect_normal(hit, {-1, 0, 0});
  // Off axis at y = 0.5: ((x - 10)/2)^2 = 0.75, normal ~ gradient ((x-10)/4, y/1, 0).
  hit = expect_hit(caster, {0, 0.5f, 0}, {1, 0, 0});
  const float dx = -2.0f * std::sqrt(0.75f);
  EXPECT_NEAR(hit.range_m, 10.0f + dx, kTol);
  expect_normal(hit, Eigen::Vector3f(dx / 4.0f, 0.5f, 0.0f).normalized());
  // Along +y at z = 0.25: y^2 + (0.25/0.5)^2 = 1, normal ~ (0, y, z / 0.25).
  hit = expect_hit(caster, {10, -5, 0.25f}, {0, 1, 0});
  const float y = -std::sqrt(0.75f);
  EXPECT_NEAR(hit.range_m, 5.0f + y, kTol);
  expect_normal(hit, Eigen::Vector3f(0.0f, y, 1.0f).normalized());
  // Oblique ray at a known surface point p: the hit distance is |p - o|.
  // ((x-10)/2)^2 + y^2 + (z/0.5)^2 = 0.36 + 0.2304 + 0.4096 = 1.
  const float pz = 0.5f * std::sqrt(1.0f - 0.36f - 0.2304f);
  const Eigen::Vector3f ps(11.2f, 0.48f, pz);
  const Eigen::Vector3f o(20, 5, 5);
  hit = expect_hit(caster, o, (ps - o).normalized());
  EXPECT_NEAR(hit.range_m, (ps - o).norm(), 1e-3f);
  expect_normal(hit, Eigen::Vector3f(0.6f / 2.0f, 0.48f, pz / 0.25f).normalized());
  // Misses.
  EXPECT_FALSE(caster.cast({0, 1.01f, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 0.51f}, {1, 0, 0}, 0.0f, 100.0f, &hit));
}

TEST(RayCasterPrimitives, TriangleIsTwoSided) {
  const RayCaster caster(Scene{Primitive::triangle({5, -1, -1}, {5, 1, -1}, {5, 0, 1}, 5, 0.5f)});
  RayHit hit = expect_hit(caster, {0, 0, 0}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 5.0f, kTol);
  expect_normal(hit, {-1, 0, 0});
  hit = expect_hit(caster, {10, 0, 0}, {-1, 0, 0});
  EXPECT_NEAR(hit.range_m, 5.0f, kTol);
  expect_normal(hit, {1, 0, 0});
  // Oblique: towards (5, 0.2, -0.5).
  const Eigen::Vector3f to(5, 0.2f, -0.5f);
  hit = expect_hit(caster, {0, 0, 0}, to.normalized());
  EXPECT_NEAR(hit.range_m, to.norm(), kTol);
  expect_normal(hit, {-1, 0, 0});
  // Outside the edges; parallel to the plane.
  EXPECT_FALSE(caster.cast({0, 0.8f, 0.5f}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, -1.1f}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({5, -5, 0}, {0, 1, 0}, 0.0f, 100.0f, &hit));
}

TEST(RayCasterPrimitives, GroundMeshHasNoCracksAlongSharedEdges) {
  // A 5 m triangle grid; rays aimed exactly at shared edges and vertices must hit.
  Scene scene;
  for (int i = -4; i < 4; ++i) {
    for (int j = -4; j < 4; ++j) {
      const float x0 = 5.0f * i, y0 = 5.0f * j;
      const Eigen::Vector3f a(x0, y0, 0), b(x0 + 5, y0, 0), c(x0 + 5, y0 + 5, 0), d(x0, y0 + 5, 0);
      scene.push_back(Primitive::triangle(a, b, c, 40, 0.3f));
      scene.push_back(Primitive::triangle(a, c, d, 40, 0.3f));
    }
  }
  const RayCaster caster(scene);
  const Eigen::Vector3f origin(0.37f, -0.21f, 1.73f);
  int misses = 0;
  for (int i = -3; i <= 3; ++i) {
    for (int j = -3; j <= 3; ++j) {
      for (float f : {0.0f, 0.5f, 0.25f}) {
        // Points on grid lines, on diagonals and at vertices.
        const Eigen::Vector3f targets[3] = {
            {5.0f * i, 5.0f * (j + f), 0}, {5.0f * (i + f), 5.0f * j, 0}, {5.0f * (i + f), 5.0f * (j + f), 0}};
        for (const Eigen::Vector3f& t : targets) {
          RayHit hit;
          if (!caster.cast(origin, (t - origin).normalized(), 0.0f, 100.0f, &hit)) {
            ++misses;
          } else {
            EXPECT_NEAR(hit.range_m, (t - origin).norm(), 1e-3f);
          }
        }
      }
    }
  }
  EXPECT_EQ(misses, 0);
}

// ---------------------------------------------------------------------------------------
// Range limits and rays starting inside.

TEST(RayCasterRange, MinAndMaxRangeAreRespected) {
  const RayCaster caster(Scene{Primitive::box({10, 0, 0}, {1, 1, 1}, 0.0f, 1, 0.5f),
                               Primitive::triangle({20, -5, -5}, {20, 5, -5}, {20, 0, 5}, 2, 0.5f)});
  RayHit hit;
  ASSERT_TRUE(caster.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_NEAR(hit.range_m, 9.0f, kTol);
  // Max range before the box: nothing.
  EXPECT_FALSE(caster.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 8.99f, &hit));
  // Inclusive bounds.
  ASSERT_TRUE(caster.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 9.0f, &hit));
  EXPECT_NEAR(hit.range_m, 9.0f, kTol);
  // Min range past the entry: the box's far side (exit at 11) is returned, facing the ray.
  ASSERT_TRUE(caster.cast({0, 0, 0}, {1, 0, 0}, 9.5f, 100.0f, &hit));
  EXPECT_NEAR(hit.range_m, 11.0f, kTol);
  EXPECT_EQ(hit.label, 1u);
  expect_normal(hit, {-1, 0, 0});
  // Min range past the whole box: the triangle.
  ASSERT_TRUE(caster.cast({0, 0, 0}, {1, 0, 0}, 11.5f, 100.0f, &hit));
  EXPECT_NEAR(hit.range_m, 20.0f, kTol);
  EXPECT_EQ(hit.label, 2u);
  // Min range past everything, and an empty interval.
  EXPECT_FALSE(caster.cast({0, 0, 0}, {1, 0, 0}, 20.5f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 0}, {1, 0, 0}, 5.0f, 4.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 0}, {1, 0, 0}, std::nanf(""), 100.0f, &hit));
}

TEST(RayCasterRange, RayStartingInsideHitsTheFarSide) {
  const RayCaster caster(Scene{Primitive::box({0, 0, 0}, {2, 1, 1}, 0.3f, 1, 0.5f)});
  RayHit hit = expect_hit(caster, {0, 0, 0}, {0, 0, 1});
  EXPECT_NEAR(hit.range_m, 1.0f, kTol);
  expect_normal(hit, {0, 0, -1});  // faces the ray
  const RayCaster sphere(Scene{Primitive::ellipsoid({0, 0, 0}, {3, 3, 3}, 2, 0.5f)});
  hit = expect_hit(sphere, {1, 0, 0}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 2.0f, kTol);
  expect_normal(hit, {-1, 0, 0});
  const RayCaster cyl(Scene{Primitive::cylinder({0, 0, 0}, 1.0f, 4.0f, 3, 0.5f)});
  hit = expect_hit(cyl, {0, 0, 1}, {0, 0, 1});
  EXPECT_NEAR(hit.range_m, 3.0f, kTol);
  expect_normal(hit, {0, 0, -1});
  hit = expect_hit(cyl, {0, 0, 1}, {0, -1, 0});
  EXPECT_NEAR(hit.range_m, 1.0f, kTol);
  expect_normal(hit, {0, 1, 0});
}

TEST(RayCasterRange, FlatBoxAndDiscAreHittable) {
  // Zero thickness is allowed for boxes (signs, panels) and cylinders (discs).
  const RayCaster caster(
      Scene{Primitive::box({5, 0, 0}, {0, 1, 1}, 0.0f, 1, 0.5f), Primitive::cylinder({0, 0, -3}, 1.0f, 0.0f, 2, 0.5f)});
  RayHit hit = expect_hit(caster, {0, 0.5f, 0.5f}, {1, 0, 0});
  EXPECT_NEAR(hit.range_m, 5.0f, kTol);
  EXPECT_EQ(hit.label, 1u);
  expect_normal(hit, {-1, 0, 0});
  hit = expect_hit(caster, {0.2f, 0.1f, 0}, {0, 0, -1});
  EXPECT_NEAR(hit.range_m, 3.0f, kTol);
  EXPECT_EQ(hit.label, 2u);
  expect_normal(hit, {0, 0, 1});
}

// ---------------------------------------------------------------------------------------
// Degenerate input.

TEST(RayCasterRobustness, DegeneratePrimitivesAreSkipped) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  Scene scene = {
      Primitive::box({1, 0, 0}, {0, 0, 0}, 0.0f, 100, 0.5f),            // zero size
      Primitive::box({1, 0, 0}, {0, 1, 0}, 0.0f, 101, 0.5f),            // a line, no area
      Primitive::box({1, 0, 0}, {-1, 1, 1}, 0.0f, 102, 0.5f),           // negative extent
      Primitive::box({nan, 0, 0}, {1, 1, 1}, 0.0f, 103, 0.5f),          // NaN centre
      Primitive::box({1, 0, 0}, {1, 1, 1}, nan, 104, 0.5f),             // NaN yaw
      Primitive::box({inf, 0, 0}, {1, 1, 1}, 0.0f, 105, 0.5f),          // infinite
      Primitive::cylinder({1, 0, 0}, 0.0f, 2.0f, 106, 0.5f),            // zero radius
      Primitive::cylinder({1, 0, 0}, -1.0f, 2.0f, 107, 0.5f),           // negative radius
      Primitive::cylinder({1, 0, 0}, 1.0f, nan, 108, 0.5f),             // NaN height
      Primitive::ellipsoid({1, 0, 0}, {1, 0, 1}, 109, 0.5f),            // zero semi-axis
      Primitive::ellipsoid({1, 0, 0}, {1, 1, 1e-45f}, 110, 0.5f),       // denormal semi-axis
      Primitive::triangle({1, 0, 0}, {1, 0, 0}, {1, 1, 0}, 111, 0.5f),  // repeated vertex
      Primitive::triangle({1, 0, 0}, {2, 0, 0}, {3, 0, 0}, 112, 0.5f),  // colinear
      Primitive::triangle({1, 0, 0}, {2, nan, 0}, {3, 1, 0}, 113, 0.5f),
      Primitive::box({3e38f, 0, 0}, {3e38f, 1, 1}, 0.0f, 114, 0.5f),  // AABB overflows
  };
  Primitive bogus_shape = Primitive::box({1, 0, 0}, {1, 1, 1}, 0.0f, 115, 0.5f);
  bogus_shape.shape = static_cast<Shape>(17);
  scene.push_back(bogus_shape);
  {
    const RayCaster only_degenerate(scene);
    EXPECT_EQ(only_degenerate.primitive_count(), 0u);
    RayHit hit;
    EXPECT_FALSE(only_degenerate.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  }
  scene.push_back(Primitive::box({10, 0, 0}, {1, 1, 1}, 0.0f, 7, 2.0f));  // refl clamped
  const RayCaster caster(scene);
  EXPECT_EQ(caster.primitive_count(), 1u);
  RayHit hit;
  ASSERT_TRUE(caster.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_EQ(hit.label, 7u);
  EXPECT_NEAR(hit.range_m, 9.0f, kTol);
  EXPECT_LE(hit.reflectivity, 1.0f);
}

TEST(RayCasterRobustness, EmptySceneAndBadRays) {
  const RayCaster empty(Scene{});
  EXPECT_EQ(empty.primitive_count(), 0u);
  RayHit hit;
  EXPECT_FALSE(empty.cast({0, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  const RayCaster caster(Scene{Primitive::box({5, 0, 0}, {1, 1, 1}, 0.0f, 1, 0.5f)});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(caster.cast({nan, 0, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_FALSE(caster.cast({0, 0, 0}, {nan, 0, 0}, 0.0f, 100.0f, &hit));
  // A ray exactly in a face plane may hit or miss, but must not crash or return garbage.
  if (caster.cast({0, 1, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit)) {
    EXPECT_NEAR(hit.range_m, 4.0f, kTol);
  }
  EXPECT_FALSE(caster.cast({0, 1.5f, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
  EXPECT_TRUE(caster.cast({0, 0.999f, 0}, {1, 0, 0}, 0.0f, 100.0f, &hit));
}

}  // namespace
}  // namespace segmatch::sim
