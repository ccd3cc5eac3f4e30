// Primitive factory functions. They store the arguments as given; validation (degenerate or
// non-finite primitives) happens once, when a RayCaster is built (see raycaster.cpp).
#include "segmatch/sim/scene.h"

namespace segmatch::sim {

Primitive Primitive::box(const Eigen::Vector3f& centre, const Eigen::Vector3f& half_extents, float yaw, uint32_t label,
                         float reflectivity) {
  Primitive p;
  p.shape = Shape::kBox;
  p.a = centre;
  p.b = half_extents;
  p.yaw = yaw;
  p.label = label;
  p.reflectivity = reflectivity;
  return p;
}

Primitive Primitive::cylinder(const Eigen::Vector3f& base_centre, float radius, float height, uint32_t label,
                              float reflectivity) {
  Primitive p;
  p.shape = Shape::kCylinder;
  p.a = base_centre;
  p.b = Eigen::Vector3f(radius, radius, height);
  p.label = label;
  p.reflectivity = reflectivity;
  return p;
}

Primitive Primitive::ellipsoid(const Eigen::Vector3f& centre, const Eigen::Vector3f& semi_axes, uint32_t label,
                               float reflectivity) {
  Primitive p;
  p.shape = Shape::kEllipsoid;
  p.a = centre;
  p.b = semi_axes;
  p.label = label;
  p.reflectivity = reflectivity;
  return p;
}

Primitive Primitive::triangle(const Eigen::Vector3f& v0, const Eigen::Vector3f& v1, const Eigen::Vector3f& v2,
                              uint32_t label, float reflectivity) {
  Primitive p;
  p.shape = Shape::kTriangle;
  p.a = v0;
  p.b = v1;
  p.c = v2;
  p.label = label;
  p.reflectivity = reflectivity;
  return p;
}

}  // namespace segmatch::sim
