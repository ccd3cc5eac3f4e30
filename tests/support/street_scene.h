// A synthetic street for localizer tests: poles, and optionally distinct objects (cars, kiosks,
// walls...) sampled densely (3 cm, so 0.1 m voxels get their >= 2 points). Known answers: the
// street with objects localizes at the true pose, the poles alone are ambiguous.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/core/localization/localizer.h>
#include <segmatch/core/segmentation/segment.h>

#include <cmath>

namespace segmatch {
namespace test {

// Dense surface samples (spacing 3 cm, so 0.1 m voxels get their >= 2 points).
inline void add_cylinder(PointCloud& cloud, float x, float y, float radius, float height) {
  const int around = static_cast<int>(2 * M_PI * radius / 0.03f);
  for (float z = 0.f; z < height; z += 0.03f)
    for (int k = 0; k < around; ++k) {
      const float a = 2.f * static_cast<float>(M_PI) * k / around;
      cloud.push_back(Point{x + radius * std::cos(a), y + radius * std::sin(a), z, 0.f});
    }
}

inline void add_box(PointCloud& cloud, float x, float y, float sx, float sy, float sz) {
  for (float u = 0.f; u <= sx; u += 0.03f)
    for (float w = 0.f; w <= sz; w += 0.03f) {
      cloud.push_back(Point{x + u, y, w, 0.f});
      cloud.push_back(Point{x + u, y + sy, w, 0.f});
    }
  for (float v = 0.f; v <= sy; v += 0.03f)
    for (float w = 0.f; w <= sz; w += 0.03f) {
      cloud.push_back(Point{x, y + v, w, 0.f});
      cloud.push_back(Point{x + sx, y + v, w, 0.f});
    }
}

inline PointCloud pole_street(bool with_distinct_objects) {
  PointCloud cloud;
  for (int i = 0; i < 10; ++i) add_cylinder(cloud, 6.f * i, 4.f, 0.15f, 4.f);
  if (with_distinct_objects) {
    add_box(cloud, 3.f, -6.f, 4.2f, 1.8f, 1.5f);  // a car
    add_box(cloud, 15.f, -7.f, 2.f, 2.f, 2.5f);   // a kiosk
    add_box(cloud, 26.f, -5.f, 1.f, 3.f, 1.f);    // a bench
    add_box(cloud, 35.f, 8.f, 6.f, 0.4f, 2.f);    // a wall
    add_cylinder(cloud, 47.f, -6.f, 0.6f, 1.2f);  // a bin
    add_cylinder(cloud, 20.f, 9.f, 1.2f, 0.9f);   // a planter
    add_box(cloud, 52.f, 9.f, 1.5f, 1.5f, 3.2f);  // a cabinet
  }
  return cloud;
}

// The pole street with two loading platforms: walls alone leave the height free (degenerate),
// the platforms' tops hold it, as car roofs and kerbs do in a real street.
inline PointCloud street_with_platforms() {
  PointCloud cloud = pole_street(true);
  for (const Eigen::Vector4f& b : {Eigen::Vector4f(5.f, 12.f, 10.f, 4.f), Eigen::Vector4f(38.f, -14.f, 8.f, 3.f)}) {
    add_box(cloud, b[0], b[1], b[2], b[3], 1.2f);
    for (float u = 0.f; u <= b[2]; u += 0.03f)
      for (float v = 0.f; v <= b[3]; v += 0.03f) cloud.push_back(Point{b[0] + u, b[1] + v, 1.2f, 0.f});
  }
  return cloud;
}

inline PointCloud transformed(const PointCloud& cloud, const Pose3d& T) {
  PointCloud out = cloud;
  for (Point& p : out) {
    const Eigen::Vector3f q = T.cast<float>() * p.xyz();
    p.x = q.x(), p.y = q.y(), p.z = q.z();
  }
  return out;
}

// A map's surface layer held in memory (the server reads it from the map file's tiles).
class InMemorySurfaces : public MapSurfaces {
 public:
  explicit InMemorySurfaces(PointCloud points) : points_(std::move(points)) {}
  PointCloud near(const Eigen::Vector3d& centre, double radius_m) const override {
    return crop_cylinder(points_, centre, radius_m);
  }

 private:
  PointCloud points_;
};

// The scene with flat ground under it (x -10..60 m, y -20..20 m, 0.1 m grid): what a surface
// layer holds and segments leave out.
inline PointCloud with_ground(PointCloud cloud) {
  for (float x = -10.f; x <= 60.f; x += 0.1f)
    for (float y = -20.f; y <= 20.f; y += 0.1f) cloud.push_back(Point{x, y, 0.f, 0.f});
  return cloud;
}

// L2 matching on eigen features (the scene is too small to train a forest on), no ground.
inline LocalizerConfig street_localizer_config() {
  LocalizerConfig c;
  c.segmentation.ground.method = GroundRemoval::kNone;  // no ground in these scenes
  c.segmentation.descriptors.compute_esf = false;
  c.matcher.type = MatcherType::kL2;
  c.matcher.use_shapes = false;
  c.matcher.l2_threshold = 0.6f;
  c.min_support = 6;
  return c;
}

}  // namespace test
}  // namespace segmatch
