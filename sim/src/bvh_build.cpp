// The ray caster's BVH build (raycaster.cpp describes the structure): primitives packed into
// their intersection-ready form, binned SAH over their AABBs, collapse into wide nodes.
#include "bvh.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace segmatch::sim::bvh {
namespace {

bool finite3(const Eigen::Vector3f& v) { return v.allFinite(); }

// Pads a primitive's box slightly so that float rounding in the node slab test (and the
// barycentric tolerance of triangles) can never cull a true hit; false if it is not finite.
bool pad_box(Aabb* box) {
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

// A yawed box: centre, half extents, cos and sin of the yaw; its AABB.
bool pack_box(const Primitive& in, PackedPrim* out, Aabb* box) {
  const Eigen::Vector3f& a = in.a;
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
  return true;
}

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
    case Shape::kBox:
      if (!pack_box(in, out, box)) return false;
      break;
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
    default: return false;
  }
  return pad_box(box);
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

  // The binned SAH split of prims_[begin, end) into nb bins per axis (axis -1: none, all
  // centroids coincide).
  struct Split {
    int axis = -1, bin = 0;
    float cost = std::numeric_limits<float>::infinity();
    float scale[3] = {0.0f, 0.0f, 0.0f};  // bins per metre on each axis
  };
  Split sah_split(uint32_t begin, uint32_t end, const Aabb& cb, int nb) const {
    Split best;
    // One pass bins all three axes.
    Aabb bins[3][kNumBins];
    uint32_t counts[3][kNumBins] = {};
    for (int axis = 0; axis < 3; ++axis) {
      const float ext = cb.hi[axis] - cb.lo[axis];
      best.scale[axis] = ext > 0.0f ? static_cast<float>(nb) / ext : 0.0f;
    }
    for (uint32_t i = begin; i < end; ++i) {
      const BuildPrim& p = prims_[i];
      for (int axis = 0; axis < 3; ++axis) {
        const int bi = bin_of(p.centre[axis], cb.lo[axis], best.scale[axis], nb);
        bins[axis][bi].grow(p.box);
        ++counts[axis][bi];
      }
    }
    for (int axis = 0; axis < 3; ++axis) {
      if (!(best.scale[axis] > 0.0f)) continue;
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
        const float cost =
            acc.half_area() * static_cast<float>(cnt) + right_area[i] * static_cast<float>(right_count[i]);
        if (cost < best.cost) {
          best.cost = cost;
          best.axis = axis;
          best.bin = i;
        }
      }
    }
    return best;
  }

  // Subtree over prims_[begin, end) with the given bounds and centroid bounds.
  uint32_t build(uint32_t begin, uint32_t end, const Aabb& bounds, const Aabb& cb, int depth) {
    const uint32_t n = end - begin;
    if (n == 1) return make_leaf(begin, end, bounds);
    // Fewer bins for small nodes: the sweep would cost more than the binning.
    const int nb = static_cast<int>(std::min<uint32_t>(kNumBins, std::max<uint32_t>(4, n)));
    const Split sah = depth < kMaxSahDepth ? sah_split(begin, end, cb, nb) : Split{};
    const int best_axis = sah.axis, best_split = sah.bin;
    const float best_cost = sah.cost;
    const float* scale = sah.scale;

    uint32_t mid = begin + n / 2;
    if (best_axis >= 0) {
      const float area = bounds.half_area();
      const float split_cost =
          kTraversalCost + kIntersectionCost * (area > 0.0f ? best_cost / area : static_cast<float>(n));
      const float leaf_cost = kIntersectionCost * static_cast<float>(n);
      if (n <= kMaxLeafSize && leaf_cost <= split_cost) return make_leaf(begin, end, bounds);
      const int axis = best_axis, split = best_split;
      const float lo = cb.lo[axis], sc = scale[axis];
      auto it = std::partition(prims_.begin() + begin, prims_.begin() + end,
                               [&](const BuildPrim& p) { return bin_of(p.centre[axis], lo, sc, nb) < split; });
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
                       [&](const BuildPrim& x, const BuildPrim& y) { return x.centre[axis] < y.centre[axis]; });
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

Bvh build(const Scene& scene) {
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
  if (packed.empty()) return {};
  if (packed.size() > kMaxPrimitives) {
    throw std::length_error("RayCaster: too many primitives");
  }
  std::vector<uint32_t> order;
  Bvh bvh;
  Builder(&build_prims).run(&bvh.nodes, &order);
  bvh.prims.resize(order.size());
  for (size_t i = 0; i < order.size(); ++i) bvh.prims[i] = packed[order[i]];
  return bvh;
}

}  // namespace segmatch::sim::bvh
