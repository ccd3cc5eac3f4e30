// Ray casting against a Scene through a bounding volume hierarchy.
#pragma once

#include "segmatch/sim/scene.h"

#include <Eigen/Core>

#include <cstdint>
#include <memory>

namespace segmatch::sim {

struct RayHit {
  float range_m = 0.0f;                               // distance along the (unit) ray direction
  uint32_t label = 0;                                 // label of the primitive hit
  float reflectivity = 0.0f;                          // reflectivity of the primitive hit
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();  // unit surface normal at the hit, facing the ray
};

class RayCaster {
 public:
  // Builds the acceleration structure once; the scene is copied into it.
  explicit RayCaster(const Scene& scene);
  ~RayCaster();
  RayCaster(RayCaster&&) noexcept;
  RayCaster& operator=(RayCaster&&) noexcept;

  // Nearest hit along origin + t * direction for t in [min_range_m, max_range_m];
  // direction must be unit length. A ray that starts inside a solid primitive hits its far
  // side. Thread-safe (const, no shared mutable state).
  bool cast(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float min_range_m, float max_range_m,
            RayHit* hit) const;

  size_t primitive_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace segmatch::sim
