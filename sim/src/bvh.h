// The ray caster's bounding volume hierarchy (raycaster.cpp describes it): the packed
// primitives, the wide nodes and their build (bvh_build.cpp). Private to the simulator.
#pragma once

#include "segmatch/sim/scene.h"

#include <cstdint>
#include <limits>
#include <vector>

#include <segmatch/core/detail/simd.h>

namespace segmatch::sim::bvh {

constexpr uint32_t kLeafBit = 0x80000000u;
constexpr uint32_t kLeafCountBits = 4;  // leaf ref: kLeafBit | first << 4 | count
constexpr uint32_t kLeafCountMask = (1u << kLeafCountBits) - 1u;
constexpr uint32_t kMaxLeafSize = 8;  // must be <= kLeafCountMask
constexpr uint32_t kMaxPrimitives = (kLeafBit >> kLeafCountBits) - 1u;
constexpr int kNumBins = 16;
constexpr int kMaxSahDepth = 48;  // deeper subtrees are split at the object median
constexpr int kWidth = 8;         // children per node (a multiple of 4)
// Max stack use: (kWidth - 1) pushes per level; levels <= kMaxSahDepth + log2(kMaxPrimitives).
constexpr int kStackSize = (kWidth - 1) * (kMaxSahDepth + 32) + 16;
constexpr float kTraversalCost = 1.0f;
constexpr float kIntersectionCost = 1.5f;
// Conservative widening of the node slab test's far distance (Ize 2013, 1 + 2*gamma(3)).
constexpr float kFarScale = 1.0f + 4.0f * std::numeric_limits<float>::epsilon();
// Barycentric tolerance that closes the float cracks along edges shared by mesh triangles.
constexpr float kBaryEps = 1e-5f;

inline float safe_inv(float d) {
  if (std::fabs(d) < 1e-30f) return d >= 0.0f ? 1e30f : -1e30f;
  return 1.0f / d;
}

struct Ray {
  float o[3];
  float d[3];
  float inv[3];
};

// 64 bytes, one cache line. Layout of f[] by shape:
//   kBox:       centre(0..2) half extents(3..5) cos yaw(6) sin yaw(7)
//   kCylinder:  base centre(0..2) radius(3) top z(4) radius^2(5)
//   kEllipsoid: centre(0..2) 1/semi-axes(3..5)
//   kTriangle:  v0(0..2) e1 = v1 - v0 (3..5) e2 = v2 - v0 (6..8)
struct alignas(64) PackedPrim {
  float f[12];
  uint32_t shape;
  uint32_t index;  // index in the input scene (tie-breaking)
  uint32_t label;
  float reflectivity;
};
static_assert(sizeof(PackedPrim) == 64, "PackedPrim must be one cache line");

// Wide node: the AABBs of up to kWidth children, structure-of-arrays so that SSE tests
// four children per instruction. Unused slots hold an inverted, infinite box (never hit)
// and an empty leaf ref.
struct alignas(64) Node {
  float b[3][2][kWidth];   // [axis][lo/hi][child]
  uint32_t child[kWidth];  // node index, or leaf ref (kLeafBit set)
};
static_assert(sizeof(Node) % 64 == 0, "Node must fill whole cache lines");
constexpr int kAxisStride = 2 * kWidth * static_cast<int>(sizeof(float));  // bytes
constexpr int kHiOffset = kWidth * static_cast<int>(sizeof(float));        // bytes

// Axis-aligned box; 4 lanes (the 4th is padding) so that grow() is two SSE instructions.
struct alignas(16) Aabb {
  float lo[4] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity(), 0.0f};
  float hi[4] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity(), 0.0f};

  // Lane-wise as one four-float min and max (segmatch/core/detail/simd.h); the 4th lane is unused.
  void grow(const Aabb& o) {
    simd::store(lo, simd::min(simd::load(lo), simd::load(o.lo)));
    simd::store(hi, simd::max(simd::load(hi), simd::load(o.hi)));
  }
  // p: 4 floats, the 4th ignored (must be finite).
  void grow_point(const float* p) {
    const simd::F4 v = simd::load(p);
    simd::store(lo, simd::min(simd::load(lo), v));
    simd::store(hi, simd::max(simd::load(hi), v));
  }
  float half_area() const {
    const float dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
    if (!(dx >= 0.0f)) return 0.0f;  // empty
    return dx * dy + dy * dz + dz * dx;
  }
};

struct alignas(16) BuildPrim {
  Aabb box;
  float centre[4];  // 4th lane 0
  uint32_t id;      // position in the packed primitive array
};

// The primitives in leaf order and the nodes over them (nodes[0] is the root; none if the
// scene has no valid primitive). Throws std::length_error beyond kMaxPrimitives.
struct Bvh {
  std::vector<Node> nodes;
  std::vector<PackedPrim> prims;
};
Bvh build(const Scene& scene);

}  // namespace segmatch::sim::bvh
