// Ray casting against a Scene through a bounding volume hierarchy (BVH).
//
// Build: binned SAH (16 bins per axis, centroid binning, one pass bins all three axes)
// over the primitives' tight world-space AABBs gives a binary tree, which is collapsed into
// 8-wide nodes (repeatedly opening the child with the largest surface area) flattened
// depth-first into one array. A node stores its children's AABBs structure-of-arrays, so
// four-lane SIMD (segmatch/core/simd.h) tests four children at a time. Leaves hold up to kMaxLeafSize primitives,
// stored contiguously in leaf order in a packed, intersection-ready form (precomputed yaw
// sin/cos, triangle edges, inverse semi-axes, ...). Degenerate primitives (non-finite
// values, negative or zero size, zero-area triangles) are skipped.
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

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <vector>

#include <segmatch/core/simd.h>

namespace segmatch::sim {
namespace {

constexpr uint32_t kLeafBit = 0x80000000u;
constexpr uint32_t kLeafCountBits = 4;  // leaf ref: kLeafBit | first << 4 | count
constexpr uint32_t kLeafCountMask = (1u << kLeafCountBits) - 1u;
constexpr uint32_t kMaxLeafSize = 8;  // must be <= kLeafCountMask
constexpr uint32_t kMaxPrimitives = (kLeafBit >> kLeafCountBits) - 1u;
constexpr int kNumBins = 16;
constexpr int kMaxSahDepth = 48;   // deeper subtrees are split at the object median
constexpr int kWidth = 8;  // children per node (a multiple of 4)
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

// ---------------------------------------------------------------------------------------
// Exact primitive intersection. Each returns true with *t in [tmin, tmax] and a face code
// used afterwards to compute the normal.

inline bool select_t(float tnear, float tfar, float tmin, float tmax, float* t, bool* exit) {
  if (!(tnear <= tfar)) return false;
  if (tnear >= tmin) {
    if (tnear > tmax) return false;
    *t = tnear;
    *exit = false;
    return true;
  }
  if (tfar >= tmin && tfar <= tmax) {
    *t = tfar;
    *exit = true;
    return true;
  }
  return false;
}

inline bool intersect_box(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t,
                          int* face) {
  const float c = p.f[6], s = p.f[7];
  const float rx = r.o[0] - p.f[0], ry = r.o[1] - p.f[1], rz = r.o[2] - p.f[2];
  // Into the box frame: rotate by -yaw about z.
  const float lox = c * rx + s * ry;
  const float loy = c * ry - s * rx;
  const float ldx = c * r.d[0] + s * r.d[1];
  const float ldy = c * r.d[1] - s * r.d[0];
  const float ilx = safe_inv(ldx), ily = safe_inv(ldy), ilz = r.inv[2];
  const float hx = p.f[3], hy = p.f[4], hz = p.f[5];
  const float tx0 = (-hx - lox) * ilx, tx1 = (hx - lox) * ilx;
  const float ty0 = (-hy - loy) * ily, ty1 = (hy - loy) * ily;
  const float tz0 = (-hz - rz) * ilz, tz1 = (hz - rz) * ilz;
  const float nx = std::min(tx0, tx1), fx = std::max(tx0, tx1);
  const float ny = std::min(ty0, ty1), fy = std::max(ty0, ty1);
  const float nz = std::min(tz0, tz1), fz = std::max(tz0, tz1);
  const float tnear = std::max(nx, std::max(ny, nz));
  const float tfar = std::min(fx, std::min(fy, fz));
  bool exit = false;
  if (!select_t(tnear, tfar, tmin, tmax, t, &exit)) return false;
  if (!exit) {
    *face = (tnear == nx) ? 0 : (tnear == ny ? 1 : 2);
  } else {
    *face = (tfar == fx) ? 0 : (tfar == fy ? 1 : 2);
  }
  return true;
}

// Roots of a*t^2 + 2*b*t + c = 0 with the discriminant given precisely as disc = b^2 - a*c
// (computed by the caller in a cancellation-free form). Returns false if no real root.
inline bool solve_quadratic(float a, float b, float c, float disc, float* t0, float* t1) {
  if (disc < 0.0f) return false;
  const float sq = std::sqrt(disc);
  const float q = -(b + std::copysign(sq, b));
  if (q == 0.0f) {
    *t0 = *t1 = 0.0f;  // b == 0 and disc == 0: tangent at the closest point t = 0
    return true;
  }
  const float ra = q / a, rb = c / q;
  *t0 = std::min(ra, rb);
  *t1 = std::max(ra, rb);
  return true;
}

inline bool intersect_cylinder(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t,
                               int* face) {
  const float px = r.o[0] - p.f[0], py = r.o[1] - p.f[1];
  const float dx = r.d[0], dy = r.d[1];
  const float rr = p.f[5];
  const float a = dx * dx + dy * dy;
  float ts0, ts1;
  if (a > 0.0f) {
    const float b = px * dx + py * dy;
    const float c = px * px + py * py - rr;
    const float cr = px * dy - py * dx;
    if (!solve_quadratic(a, b, c, rr * a - cr * cr, &ts0, &ts1)) return false;
  } else {  // vertical ray: inside the infinite cylinder everywhere or nowhere
    if (px * px + py * py > rr) return false;
    ts0 = -std::numeric_limits<float>::infinity();
    ts1 = std::numeric_limits<float>::infinity();
  }
  const float tz0 = (p.f[2] - r.o[2]) * r.inv[2], tz1 = (p.f[4] - r.o[2]) * r.inv[2];
  const float nz = std::min(tz0, tz1), fz = std::max(tz0, tz1);
  const float tnear = std::max(ts0, nz), tfar = std::min(ts1, fz);
  bool exit = false;
  if (!select_t(tnear, tfar, tmin, tmax, t, &exit)) return false;
  if (!exit) {
    *face = (tnear == ts0) ? 0 : 1;  // 0 = side, 1 = cap
  } else {
    *face = (tfar == ts1) ? 0 : 1;
  }
  return true;
}

inline bool intersect_ellipsoid(const PackedPrim& p, const Ray& r, float tmin, float tmax,
                                float* t) {
  const float sx = p.f[3], sy = p.f[4], sz = p.f[5];
  // Scale into the unit-sphere frame (the ray parameter t is unchanged).
  const float ox = (r.o[0] - p.f[0]) * sx, oy = (r.o[1] - p.f[1]) * sy,
              oz = (r.o[2] - p.f[2]) * sz;
  const float dx = r.d[0] * sx, dy = r.d[1] * sy, dz = r.d[2] * sz;
  const float a = dx * dx + dy * dy + dz * dz;
  const float b = ox * dx + oy * dy + oz * dz;
  const float c = ox * ox + oy * oy + oz * oz - 1.0f;
  const float cx = oy * dz - oz * dy, cy = oz * dx - ox * dz, cz = ox * dy - oy * dx;
  const float disc = a - (cx * cx + cy * cy + cz * cz);  // == b^2 - a*c, without cancellation
  float t0, t1;
  if (!solve_quadratic(a, b, c, disc, &t0, &t1)) return false;
  bool exit = false;
  return select_t(t0, t1, tmin, tmax, t, &exit);
}

inline bool intersect_triangle(const PackedPrim& p, const Ray& r, float tmin, float tmax,
                               float* t) {
  // Moller-Trumbore, two-sided.
  const float e1x = p.f[3], e1y = p.f[4], e1z = p.f[5];
  const float e2x = p.f[6], e2y = p.f[7], e2z = p.f[8];
  const float px = r.d[1] * e2z - r.d[2] * e2y;
  const float py = r.d[2] * e2x - r.d[0] * e2z;
  const float pz = r.d[0] * e2y - r.d[1] * e2x;
  const float det = e1x * px + e1y * py + e1z * pz;
  if (det == 0.0f) return false;
  // Reject on the unnormalised barycentrics first (no division on the common miss path).
  const float adet = std::fabs(det);
  const float sgn = det > 0.0f ? 1.0f : -1.0f;
  const float lo = -kBaryEps * adet, hi = (1.0f + kBaryEps) * adet;
  const float sx = r.o[0] - p.f[0], sy = r.o[1] - p.f[1], sz = r.o[2] - p.f[2];
  const float u = (sx * px + sy * py + sz * pz) * sgn;
  if (!(u >= lo && u <= hi)) return false;
  const float qx = sy * e1z - sz * e1y;
  const float qy = sz * e1x - sx * e1z;
  const float qz = sx * e1y - sy * e1x;
  const float v = (r.d[0] * qx + r.d[1] * qy + r.d[2] * qz) * sgn;
  if (!(v >= lo && u + v <= hi)) return false;
  const float tt = (e2x * qx + e2y * qy + e2z * qz) / det;
  if (!(tt >= tmin && tt <= tmax)) return false;
  *t = tt;
  return true;
}

inline bool intersect(const PackedPrim& p, const Ray& r, float tmin, float tmax, float* t,
                      int* face) {
  switch (static_cast<Shape>(p.shape)) {
    case Shape::kTriangle:
      return intersect_triangle(p, r, tmin, tmax, t);
    case Shape::kBox:
      return intersect_box(p, r, tmin, tmax, t, face);
    case Shape::kCylinder:
      return intersect_cylinder(p, r, tmin, tmax, t, face);
    case Shape::kEllipsoid:
      return intersect_ellipsoid(p, r, tmin, tmax, t);
  }
  return false;
}

Eigen::Vector3f surface_normal(const PackedPrim& p, const Ray& r, float t, int face) {
  Eigen::Vector3f n = Eigen::Vector3f::UnitZ();
  switch (static_cast<Shape>(p.shape)) {
    case Shape::kBox:
      if (face == 0) {
        n = Eigen::Vector3f(p.f[6], p.f[7], 0.0f);
      } else if (face == 1) {
        n = Eigen::Vector3f(-p.f[7], p.f[6], 0.0f);
      }
      break;
    case Shape::kCylinder:
      if (face == 0) {
        n = Eigen::Vector3f(r.o[0] + t * r.d[0] - p.f[0], r.o[1] + t * r.d[1] - p.f[1], 0.0f);
      }
      break;
    case Shape::kEllipsoid: {
      // Gradient of |S^-1 (x - c)|^2 is S^-2 (x - c) = S^-1 * (unit-sphere point).
      const float sx = p.f[3], sy = p.f[4], sz = p.f[5];
      const float ux = (r.o[0] - p.f[0]) * sx + t * r.d[0] * sx;
      const float uy = (r.o[1] - p.f[1]) * sy + t * r.d[1] * sy;
      const float uz = (r.o[2] - p.f[2]) * sz + t * r.d[2] * sz;
      n = Eigen::Vector3f(ux * sx, uy * sy, uz * sz);
      break;
    }
    case Shape::kTriangle:
      n = Eigen::Vector3f(p.f[3], p.f[4], p.f[5]).cross(Eigen::Vector3f(p.f[6], p.f[7], p.f[8]));
      break;
  }
  const float len = n.norm();
  if (!(len > 0.0f) || !std::isfinite(len)) {
    n = -Eigen::Vector3f(r.d[0], r.d[1], r.d[2]);  // degenerate: face the ray head-on
  } else {
    n /= len;
  }
  if (n.x() * r.d[0] + n.y() * r.d[1] + n.z() * r.d[2] > 0.0f) n = -n;
  return n;
}

// ---------------------------------------------------------------------------------------
// Build.

// Axis-aligned box; 4 lanes (the 4th is padding) so that grow() is two SSE instructions.
struct alignas(16) Aabb {
  float lo[4] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity(), 0.0f};
  float hi[4] = {-std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity(),
                 -std::numeric_limits<float>::infinity(), 0.0f};

  // Lane-wise as one four-float min and max (segmatch/core/simd.h); the 4th lane is unused.
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

bool finite3(const Eigen::Vector3f& v) { return v.allFinite(); }

// Converts a scene primitive into packed form and its world AABB; false if degenerate.
bool pack_primitive(const Primitive& in, uint32_t index, PackedPrim* out, Aabb* box) {
  std::memset(out, 0, sizeof(*out));
  out->shape = static_cast<uint32_t>(in.shape);
  out->index = index;
  out->label = in.label;
  const float refl = in.reflectivity;
  out->reflectivity = std::isfinite(refl) ? std::min(1.0f, std::max(0.0f, refl)) : 0.0f;
  if (!finite3(in.a)) return false;
  const Eigen::Vector3f& a = in.a;
  switch (in.shape) {
    case Shape::kBox: {
      const Eigen::Vector3f& h = in.b;
      if (!finite3(h) || !std::isfinite(in.yaw)) return false;
      if (h.minCoeff() < 0.0f) return false;
      if ((h.array() > 0.0f).count() < 2) return false;  // no area
      const float c = std::cos(in.yaw), s = std::sin(in.yaw);
      const float ex = std::fabs(c) * h.x() + std::fabs(s) * h.y();
      const float ey = std::fabs(s) * h.x() + std::fabs(c) * h.y();
      for (int k = 0; k < 3; ++k) out->f[k] = a[k];
      for (int k = 0; k < 3; ++k) out->f[3 + k] = h[k];
      out->f[6] = c;
      out->f[7] = s;
      *box = Aabb();
      box->lo[0] = a.x() - ex, box->hi[0] = a.x() + ex;
      box->lo[1] = a.y() - ey, box->hi[1] = a.y() + ey;
      box->lo[2] = a.z() - h.z(), box->hi[2] = a.z() + h.z();
      break;
    }
    case Shape::kCylinder: {
      const float r = in.b.x(), height = in.b.z();
      if (!std::isfinite(r) || !std::isfinite(height) || !(r > 0.0f) || !(height >= 0.0f)) {
        return false;
      }
      for (int k = 0; k < 3; ++k) out->f[k] = a[k];
      out->f[3] = r;
      out->f[4] = a.z() + height;
      out->f[5] = r * r;
      if (!(out->f[5] > 0.0f)) return false;
      box->lo[0] = a.x() - r, box->hi[0] = a.x() + r;
      box->lo[1] = a.y() - r, box->hi[1] = a.y() + r;
      box->lo[2] = a.z(), box->hi[2] = a.z() + height;
      break;
    }
    case Shape::kEllipsoid: {
      const Eigen::Vector3f& s = in.b;
      if (!finite3(s) || !(s.minCoeff() > 0.0f)) return false;
      for (int k = 0; k < 3; ++k) {
        out->f[k] = a[k];
        out->f[3 + k] = 1.0f / s[k];
        if (!std::isfinite(out->f[3 + k])) return false;
        box->lo[k] = a[k] - s[k];
        box->hi[k] = a[k] + s[k];
      }
      break;
    }
    case Shape::kTriangle: {
      if (!finite3(in.b) || !finite3(in.c)) return false;
      const Eigen::Vector3f e1 = in.b - a, e2 = in.c - a;
      const Eigen::Vector3d n = e1.cast<double>().cross(e2.cast<double>());
      const double scale = e1.cast<double>().squaredNorm() * e2.cast<double>().squaredNorm();
      if (!(n.squaredNorm() > 1e-12 * scale) || !(scale > 0.0)) return false;  // zero area
      for (int k = 0; k < 3; ++k) {
        out->f[k] = a[k];
        out->f[3 + k] = e1[k];
        out->f[6 + k] = e2[k];
        box->lo[k] = std::min(a[k], std::min(in.b[k], in.c[k]));
        box->hi[k] = std::max(a[k], std::max(in.b[k], in.c[k]));
      }
      break;
    }
    default:
      return false;
  }
  // Pad slightly so that float rounding in the node slab test (and the barycentric
  // tolerance of triangles) can never cull a true hit.
  float extent = 0.0f, mag = 0.0f;
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(box->lo[k]) || !std::isfinite(box->hi[k])) return false;
    extent = std::max(extent, box->hi[k] - box->lo[k]);
    mag = std::max(mag, std::max(std::fabs(box->lo[k]), std::fabs(box->hi[k])));
  }
  const float pad = 4.0f * kBaryEps * extent + 1e-6f * mag + 1e-6f;
  for (int k = 0; k < 3; ++k) {
    box->lo[k] -= pad;
    box->hi[k] += pad;
  }
  return true;
}

// Binned SAH builder producing a binary tree, which is then collapsed into kWidth-wide nodes.
class Builder {
 public:
  explicit Builder(std::vector<BuildPrim>* prims) : prims_(*prims) {}

  // Builds the whole tree; fills nodes (nodes[0] = root) and the leaf order of the prims.
  void run(std::vector<Node>* nodes, std::vector<uint32_t>* order) {
    order_ = order;
    order_->reserve(prims_.size());
    bnodes_.reserve(2 * prims_.size());
    Aabb bounds, cbounds;
    for (const BuildPrim& p : prims_) {
      bounds.grow(p.box);
      cbounds.grow_point(p.centre);
    }
    const uint32_t root = build(0, static_cast<uint32_t>(prims_.size()), bounds, cbounds, 0);
    nodes->clear();
    nodes->reserve(bnodes_.size() / 2 + 2);
    if (bnodes_[root].leaf_ref != 0) {  // tiny scene: a single leaf under the root node
      nodes->emplace_back(empty_node());
      set_child(&(*nodes)[0], 0, bnodes_[root].leaf_ref, bnodes_[root].box);
      return;
    }
    collapse(root, nodes);
  }

 private:
  struct BNode {
    Aabb box;
    uint32_t left = 0, right = 0;
    uint32_t leaf_ref = 0;  // != 0 for leaves
  };

  static Node empty_node() {
    Node n;
    for (int axis = 0; axis < 3; ++axis) {
      for (int c = 0; c < kWidth; ++c) {
        n.b[axis][0][c] = std::numeric_limits<float>::infinity();
        n.b[axis][1][c] = -std::numeric_limits<float>::infinity();
      }
    }
    for (int c = 0; c < kWidth; ++c) n.child[c] = kLeafBit;  // empty leaf
    return n;
  }

  static void set_child(Node* node, int slot, uint32_t ref, const Aabb& b) {
    node->child[slot] = ref;
    for (int axis = 0; axis < 3; ++axis) {
      node->b[axis][0][slot] = b.lo[axis];
      node->b[axis][1][slot] = b.hi[axis];
    }
  }

  static int bin_of(float c, float lo, float scale, int bins) {
    const int bi = static_cast<int>((c - lo) * scale);
    return std::min(bins - 1, std::max(0, bi));
  }

  uint32_t make_leaf(uint32_t begin, uint32_t end, const Aabb& bounds) {
    const uint32_t first = static_cast<uint32_t>(order_->size());
    for (uint32_t i = begin; i < end; ++i) order_->push_back(prims_[i].id);
    BNode node;
    node.box = bounds;
    node.leaf_ref = kLeafBit | (first << kLeafCountBits) | (end - begin);
    bnodes_.push_back(node);
    return static_cast<uint32_t>(bnodes_.size() - 1);
  }

  // Subtree over prims_[begin, end) with the given bounds and centroid bounds.
  uint32_t build(uint32_t begin, uint32_t end, const Aabb& bounds, const Aabb& cb, int depth) {
    const uint32_t n = end - begin;
    if (n == 1) return make_leaf(begin, end, bounds);

    int best_axis = -1;
    int best_split = 0;
    float best_cost = std::numeric_limits<float>::infinity();
    float scale[3] = {0.0f, 0.0f, 0.0f};
    // Fewer bins for small nodes: the sweep would cost more than the binning.
    const int nb = static_cast<int>(std::min<uint32_t>(kNumBins, std::max<uint32_t>(4, n)));
    if (depth < kMaxSahDepth) {
      // One pass bins all three axes.
      Aabb bins[3][kNumBins];
      uint32_t counts[3][kNumBins] = {};
      for (int axis = 0; axis < 3; ++axis) {
        const float ext = cb.hi[axis] - cb.lo[axis];
        scale[axis] = ext > 0.0f ? static_cast<float>(nb) / ext : 0.0f;
      }
      for (uint32_t i = begin; i < end; ++i) {
        const BuildPrim& p = prims_[i];
        for (int axis = 0; axis < 3; ++axis) {
          const int bi = bin_of(p.centre[axis], cb.lo[axis], scale[axis], nb);
          bins[axis][bi].grow(p.box);
          ++counts[axis][bi];
        }
      }
      for (int axis = 0; axis < 3; ++axis) {
        if (!(scale[axis] > 0.0f)) continue;
        float right_area[kNumBins];
        uint32_t right_count[kNumBins];
        Aabb acc;
        uint32_t cnt = 0;
        for (int i = nb - 1; i > 0; --i) {
          acc.grow(bins[axis][i]);
          cnt += counts[axis][i];
          right_area[i] = acc.half_area();
          right_count[i] = cnt;
        }
        acc = Aabb();
        cnt = 0;
        for (int i = 1; i < nb; ++i) {
          acc.grow(bins[axis][i - 1]);
          cnt += counts[axis][i - 1];
          if (cnt == 0 || right_count[i] == 0) continue;
          const float cost = acc.half_area() * static_cast<float>(cnt) +
                             right_area[i] * static_cast<float>(right_count[i]);
          if (cost < best_cost) {
            best_cost = cost;
            best_axis = axis;
            best_split = i;
          }
        }
      }
    }

    uint32_t mid = begin + n / 2;
    if (best_axis >= 0) {
      const float area = bounds.half_area();
      const float split_cost =
          kTraversalCost + kIntersectionCost * (area > 0.0f ? best_cost / area
                                                            : static_cast<float>(n));
      const float leaf_cost = kIntersectionCost * static_cast<float>(n);
      if (n <= kMaxLeafSize && leaf_cost <= split_cost) return make_leaf(begin, end, bounds);
      const int axis = best_axis, split = best_split;
      const float lo = cb.lo[axis], sc = scale[axis];
      auto it = std::partition(prims_.begin() + begin, prims_.begin() + end,
                               [&](const BuildPrim& p) {
                                 return bin_of(p.centre[axis], lo, sc, nb) < split;
                               });
      mid = static_cast<uint32_t>(it - prims_.begin());
      if (mid == begin || mid == end) mid = begin + n / 2;  // cannot happen; be safe
    } else {
      // All centroids coincide, or the tree got too deep: balanced object-median split.
      if (n <= kMaxLeafSize) return make_leaf(begin, end, bounds);
      int axis = 0;
      for (int k = 1; k < 3; ++k) {
        if (cb.hi[k] - cb.lo[k] > cb.hi[axis] - cb.lo[axis]) axis = k;
      }
      std::nth_element(prims_.begin() + begin, prims_.begin() + mid, prims_.begin() + end,
                       [&](const BuildPrim& x, const BuildPrim& y) {
                         return x.centre[axis] < y.centre[axis];
                       });
    }

    Aabb lb, lcb, rb, rcb;
    for (uint32_t i = begin; i < mid; ++i) {
      lb.grow(prims_[i].box);
      lcb.grow_point(prims_[i].centre);
    }
    for (uint32_t i = mid; i < end; ++i) {
      rb.grow(prims_[i].box);
      rcb.grow_point(prims_[i].centre);
    }
    const uint32_t left = build(begin, mid, lb, lcb, depth + 1);
    const uint32_t right = build(mid, end, rb, rcb, depth + 1);
    BNode node;
    node.box = bounds;
    node.left = left;
    node.right = right;
    bnodes_.push_back(node);
    return static_cast<uint32_t>(bnodes_.size() - 1);
  }

  // Emits the wide node for binary inner node `bi`: its children are gathered by
  // repeatedly opening the inner child with the largest surface area.
  uint32_t collapse(uint32_t bi, std::vector<Node>* nodes) {
    uint32_t kids[kWidth] = {bnodes_[bi].left, bnodes_[bi].right};
    int count = 2;
    while (count < kWidth) {
      int open = -1;
      float open_area = -1.0f;
      for (int c = 0; c < count; ++c) {
        const BNode& k = bnodes_[kids[c]];
        if (k.leaf_ref == 0 && k.box.half_area() > open_area) {
          open_area = k.box.half_area();
          open = c;
        }
      }
      if (open < 0) break;
      const uint32_t opened = kids[open];
      // Keep the spatial order: the two grandchildren take the opened child's place.
      for (int c = count; c > open + 1; --c) kids[c] = kids[c - 1];
      kids[open] = bnodes_[opened].left;
      kids[open + 1] = bnodes_[opened].right;
      ++count;
    }
    const uint32_t index = static_cast<uint32_t>(nodes->size());
    nodes->emplace_back(empty_node());
    for (int c = 0; c < count; ++c) {
      const BNode& k = bnodes_[kids[c]];
      const uint32_t ref = k.leaf_ref != 0 ? k.leaf_ref : collapse(kids[c], nodes);
      set_child(&(*nodes)[index], c, ref, bnodes_[kids[c]].box);
    }
    return index;
  }

  std::vector<BuildPrim>& prims_;
  std::vector<uint32_t>* order_ = nullptr;
  std::vector<BNode> bnodes_;
};

}  // namespace

struct RayCaster::Impl {
  std::vector<Node> nodes;         // nodes[0] is the root (if any primitive is valid)
  std::vector<PackedPrim> prims;   // in leaf order
};

RayCaster::RayCaster(const Scene& scene) : impl_(std::make_unique<Impl>()) {
  std::vector<PackedPrim> packed;
  std::vector<BuildPrim> build_prims;
  packed.reserve(scene.size());
  build_prims.reserve(scene.size());
  for (size_t i = 0; i < scene.size(); ++i) {
    PackedPrim pp;
    BuildPrim bp;
    if (!pack_primitive(scene[i], static_cast<uint32_t>(i), &pp, &bp.box)) continue;
    for (int k = 0; k < 3; ++k) bp.centre[k] = 0.5f * (bp.box.lo[k] + bp.box.hi[k]);
    bp.centre[3] = 0.0f;
    bp.id = static_cast<uint32_t>(packed.size());
    packed.push_back(pp);
    build_prims.push_back(bp);
  }
  if (packed.empty()) return;
  if (packed.size() > kMaxPrimitives) {
    throw std::length_error("RayCaster: too many primitives");
  }
  std::vector<uint32_t> order;
  Builder(&build_prims).run(&impl_->nodes, &order);
  impl_->prims.resize(order.size());
  for (size_t i = 0; i < order.size(); ++i) impl_->prims[i] = packed[order[i]];
}

RayCaster::~RayCaster() = default;
RayCaster::RayCaster(RayCaster&&) noexcept = default;
RayCaster& RayCaster::operator=(RayCaster&&) noexcept = default;

size_t RayCaster::primitive_count() const { return impl_ ? impl_->prims.size() : 0; }

bool RayCaster::cast(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction,
                     float min_range_m, float max_range_m, RayHit* hit) const {
  if (!impl_ || impl_->nodes.empty()) return false;
  if (!(min_range_m <= max_range_m)) return false;  // also rejects NaN
  if (!origin.allFinite() || !direction.allFinite()) return false;
  const Node* nodes = impl_->nodes.data();
  const PackedPrim* prims = impl_->prims.data();

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
        if (intersect(p, ray, tmin, tbest, &t, &face) &&
            (t < tbest || p.index < best_index)) {
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
