// Scene geometry of a generated world: a flat list of simple primitives that a ray caster
// can intersect quickly. Every primitive carries the SemanticKITTI label of the object it
// belongs to, so every simulated return is labelled exactly.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace segmatch::sim {

enum class Shape : uint8_t {
  kBox,        // oriented box: centre, half extents (x, y, z), rotated by yaw about +z
  kCylinder,   // vertical cylinder: centre of the base disc, radius, height (along +z)
  kEllipsoid,  // axis-aligned ellipsoid: centre, semi-axes (x, y, z)
  kTriangle,   // triangle: three vertices (ground mesh, roofs)
};

struct Primitive {
  Shape shape = Shape::kBox;
  // Meaning by shape:
  //   kBox:       a = centre, b = half extents, yaw = rotation about +z (rad)
  //   kCylinder:  a = base centre, b.x() = radius, b.z() = height
  //   kEllipsoid: a = centre, b = semi-axes
  //   kTriangle:  a, b, c = vertices
  Eigen::Vector3f a = Eigen::Vector3f::Zero();
  Eigen::Vector3f b = Eigen::Vector3f::Zero();
  Eigen::Vector3f c = Eigen::Vector3f::Zero();
  float yaw = 0.0f;
  uint32_t label = 0;         // SemanticKITTI: instance << 16 | class
  float reflectivity = 0.5f;  // 0..1, drives the simulated intensity

  static Primitive box(const Eigen::Vector3f& centre, const Eigen::Vector3f& half_extents, float yaw, uint32_t label,
                       float reflectivity);
  static Primitive cylinder(const Eigen::Vector3f& base_centre, float radius, float height, uint32_t label,
                            float reflectivity);
  static Primitive ellipsoid(const Eigen::Vector3f& centre, const Eigen::Vector3f& semi_axes, uint32_t label,
                             float reflectivity);
  static Primitive triangle(const Eigen::Vector3f& v0, const Eigen::Vector3f& v1, const Eigen::Vector3f& v2,
                            uint32_t label, float reflectivity);
};

using Scene = std::vector<Primitive>;

}  // namespace segmatch::sim
