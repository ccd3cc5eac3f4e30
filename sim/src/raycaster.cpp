// Ray casting against a Scene through a bounding volume hierarchy (BVH).
//
// Build: binned SAH (16 bins per axis, centroid binning, one pass bins all three axes)
// over the primitives' tight world-space AABBs gives a binary tree, which is collapsed into
// 8-wide nodes (repeatedly opening the child with the largest surface area) flattened
// depth-first into one array. A node stores its children's AABBs structure-of-arrays, so
// four-lane SIMD (segmatch/core/detail/simd.h) tests four children at a time. Leaves hold up to kMaxLeafSize
// primitives, stored contiguously in leaf order in a packed, intersection-ready form (precomputed yaw sin/cos, triangle
// edges, inverse semi-axes, ...). Degenerate primitives (non-finite values, negative or zero size, zero-area triangles)
// are skipped.
//
// Traversal: explicit stack, nearest child first; the other hit children are pushed with
// their entry distance and skipped on pop once a closer hit has been found (early-out
// against the current nearest t). The ray's inverse direction is computed once; node far
// planes are widened by a few ulps (Ize 2013) so float rounding never culls a true hit.
// Ties (two primitives hit at exactly the same t) go to the lower scene index, so the result
// never depends on the traversal order and equals a brute-force loop over the scene.
//
// Range semantics: a hit counts if its t lies in [min_range_m, max_range_m]. The solid
// primitives (box, cylinder, ellipsoid) are treated as closed convex volumes: if the entry
// point lies before min_range_m (in particular when the ray starts inside the primitive),
// the exit point (the far side, seen from inside) is reported if it lies in range.
// Triangles are two-sided. The returned normal is unit length and faces the ray
// (dot(normal, direction) <= 0).
#include "segmatch/sim/raycaster.h"

#include "bvh.h"
#include "bvh_intersect.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>

#include <segmatch/core/detail/simd.h>

namespace segmatch::sim {

using namespace bvh;

struct RayCaster::Impl {
  Bvh bvh;
};

RayCaster::RayCaster(const Scene& scene) : impl_(std::make_unique<Impl>()) { impl_->bvh = bvh::build(scene); }

RayCaster::~RayCaster() = default;
RayCaster::RayCaster(RayCaster&&) noexcept = default;
RayCaster& RayCaster::operator=(RayCaster&&) noexcept = default;

size_t RayCaster::primitive_count() const { return impl_ ? impl_->bvh.prims.size() : 0; }

bool RayCaster::cast(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float min_range_m,
                     float max_range_m, RayHit* hit) const {
  if (!impl_ || impl_->bvh.nodes.empty()) return false;
  if (!(min_range_m <= max_range_m)) return false;  // also rejects NaN
  if (!origin.allFinite() || !direction.allFinite()) return false;
  const Node* nodes = impl_->bvh.nodes.data();
  const PackedPrim* prims = impl_->bvh.prims.data();

  Ray ray;
  for (int k = 0; k < 3; ++k) {
    ray.o[k] = origin[k];
    ray.d[k] = direction[k];
    ray.inv[k] = safe_inv(direction[k]);
  }
  const float tmin = min_range_m;
  float tbest = max_range_m;
  uint32_t best = 0xFFFFFFFFu;        // position in prims
  uint32_t best_index = 0xFFFFFFFFu;  // scene index of the best primitive
  int best_face = 0;

  uint32_t stack_ref[kStackSize];
  float stack_t[kStackSize];
  int sp = 0;
  uint32_t cur = 0;

  // Byte offsets of the entry (near) and exit (far) planes inside a node, per axis.
  int near_off[3], far_off[3];
  for (int k = 0; k < 3; ++k) {
    near_off[k] = k * kAxisStride + (ray.inv[k] >= 0.0f ? 0 : kHiOffset);
    far_off[k] = k * kAxisStride + (ray.inv[k] >= 0.0f ? kHiOffset : 0);
  }
  const simd::F4 ox = simd::splat(ray.o[0]), oy = simd::splat(ray.o[1]), oz = simd::splat(ray.o[2]);
  const simd::F4 ix = simd::splat(ray.inv[0]), iy = simd::splat(ray.inv[1]), iz = simd::splat(ray.inv[2]);
  // Far planes use the inverse direction widened by kFarScale (conservative culling).
  const simd::F4 fix = simd::splat(ray.inv[0] * kFarScale), fiy = simd::splat(ray.inv[1] * kFarScale),
                 fiz = simd::splat(ray.inv[2] * kFarScale);
  const simd::F4 tmin4 = simd::splat(tmin);
  float tcull = tbest * kFarScale;  // subtrees entered beyond this cannot hold the answer
  alignas(16) float tn[kWidth];

  for (;;) {
    if (!(cur & kLeafBit)) {
      const Node& nd = nodes[cur];
      const char* base = reinterpret_cast<const char*>(&nd);
      unsigned mask = 0;
      for (int g = 0; g < kWidth; g += 4) {  // four children at a time
        const char* gb = base + g * static_cast<int>(sizeof(float));
        auto plane = [gb](int off) { return simd::load(reinterpret_cast<const float*>(gb + off)); };
        const simd::F4 nx = (plane(near_off[0]) - ox) * ix;
        const simd::F4 ny = (plane(near_off[1]) - oy) * iy;
        const simd::F4 nz = (plane(near_off[2]) - oz) * iz;
        const simd::F4 fx = (plane(far_off[0]) - ox) * fix;
        const simd::F4 fy = (plane(far_off[1]) - oy) * fiy;
        const simd::F4 fz = (plane(far_off[2]) - oz) * fiz;
        const simd::F4 near4 = simd::max(simd::max(nx, ny), simd::max(nz, tmin4));
        const simd::F4 far4 = simd::min(simd::min(fx, fy), simd::min(fz, simd::splat(tcull)));
        mask |= static_cast<unsigned>(simd::le_bits(near4, far4)) << g;
        simd::store(tn + g, near4);
      }
      if (mask == 0) goto pop;
      // Visit the nearest hit child next; push the others, farthest first.
      {
        const int c0 = __builtin_ctz(mask);
        mask &= mask - 1;
        if (mask == 0) {  // one child hit (the common case)
          cur = nd.child[c0];
          continue;
        }
        const int c1 = __builtin_ctz(mask);
        mask &= mask - 1;
        if (mask == 0) {  // two children hit
          const bool first_near = tn[c0] <= tn[c1];
          const int cn = first_near ? c0 : c1, cf = first_near ? c1 : c0;
          stack_ref[sp] = nd.child[cf];
          stack_t[sp] = tn[cf];
          ++sp;
          cur = nd.child[cn];
          continue;
        }
        // Three or more: insertion sort by descending entry distance.
        uint32_t refs[kWidth] = {nd.child[c0], nd.child[c1]};
        float ts[kWidth] = {tn[c0], tn[c1]};
        if (ts[0] < ts[1]) {
          std::swap(ts[0], ts[1]);
          std::swap(refs[0], refs[1]);
        }
        int count = 2;
        while (mask) {
          const int c = __builtin_ctz(mask);
          mask &= mask - 1;
          int j = count++;
          while (j > 0 && ts[j - 1] < tn[c]) {
            ts[j] = ts[j - 1];
            refs[j] = refs[j - 1];
            --j;
          }
          ts[j] = tn[c];
          refs[j] = nd.child[c];
        }
        for (int j = 0; j < count - 1; ++j) {
          stack_ref[sp] = refs[j];
          stack_t[sp] = ts[j];
          ++sp;
        }
        cur = refs[count - 1];
        continue;
      }
    } else {
      const uint32_t first = (cur & ~kLeafBit) >> kLeafCountBits;
      const uint32_t count = cur & kLeafCountMask;
      for (uint32_t i = first; i < first + count; ++i) {
        const PackedPrim& p = prims[i];
        float t;
        int face = 0;
        if (intersect(p, ray, tmin, tbest, &t, &face) && (t < tbest || p.index < best_index)) {
          tbest = t;
          tcull = t * kFarScale;
          best = i;
          best_index = p.index;
          best_face = face;
        }
      }
    }
  pop:
    // Pop the next subtree that may still hold a closer hit.
    for (;;) {
      if (sp == 0) goto done;
      --sp;
      if (stack_t[sp] <= tcull) {
        cur = stack_ref[sp];
        break;
      }
    }
  }
done:
  if (best == 0xFFFFFFFFu) return false;
  if (hit) {
    const PackedPrim& p = prims[best];
    hit->range_m = tbest;
    hit->label = p.label;
    hit->reflectivity = p.reflectivity;
    hit->normal = surface_normal(p, ray, tbest, best_face);
  }
  return true;
}

}  // namespace segmatch::sim
