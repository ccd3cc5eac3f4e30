// Euclidean clustering of occupied voxels (paper III-A, IV-A: distance 0.2 m, segments of
// 100 .. 15000 points) and the segment_cloud() dispatch.
//
// Points are bucketed into cubic cells of edge cluster_distance_m, so every neighbour of a
// point lies in its own or one of the 26 adjacent cells (found by a sweep over the sorted
// (x, y) columns, no hashing).
// Each cell pair is visited once and close pairs are merged with union-find; no search tree.
#include <algorithm>
#include <stdexcept>
#include <string>

#include "detail/seg_grid.h"
#include "segmatch/core/detail/simd.h"
#include "segmentation/seg_segmenters.h"

namespace segmatch {
namespace detail {
namespace {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) {
    for (size_t i = 0; i < n; ++i) parent_[i] = static_cast<uint32_t>(i);
  }
  uint32_t find(uint32_t i) {
    while (parent_[i] != i) {
      parent_[i] = parent_[parent_[i]];  // path halving
      i = parent_[i];
    }
    return i;
  }
  void set_parent(uint32_t i, uint32_t root) { parent_[i] = root; }
  // The smaller root wins, so the result does not depend on the merge order.
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a == b) return;
    if (a < b) std::swap(a, b);
    parent_[a] = b;
  }

 private:
  std::vector<uint32_t> parent_;
};

// Point positions per slot as separate x, y, z arrays, padded by kPad so that 4-wide loads
// may run past the last slot.
constexpr uint32_t kPad = 3;
struct Positions {
  std::vector<float> x, y, z;
  void resize(size_t n) { x.resize(n + kPad), y.resize(n + kPad), z.resize(n + kPad); }
};

// Bit k set if slot j + k (k < 4, j + k < end) is within sqrt(d2) of slot i. The squares are
// summed as Eigen's squaredNorm() sums them, x + (y + z), so every close / not close
// decision is bitwise the one of (a - b).squaredNorm().
int close_mask4(const Positions& p, uint32_t i, uint32_t j, uint32_t end, simd::F4 d2) {
  const simd::F4 dx = simd::load(&p.x[j]) - simd::splat(p.x[i]);
  const simd::F4 dy = simd::load(&p.y[j]) - simd::splat(p.y[i]);
  const simd::F4 dz = simd::load(&p.z[j]) - simd::splat(p.z[i]);
  const simd::F4 s = dx * dx + (dy * dy + dz * dz);
  const int mask = simd::le_bits(s, d2);
  return end - j >= 4 ? mask : mask & ((1 << (end - j)) - 1);
}

// Merges the close pairs between the slot ranges [a0, a1) and [b0, b1).
void link_ranges(const Positions& p, uint32_t a0, uint32_t a1, uint32_t b0, uint32_t b1, simd::F4 d2, bool same,
                 UnionFind* uf) {
  for (uint32_t i = a0; i < a1; ++i) {
    for (uint32_t j = same ? i + 1 : b0; j < b1; j += 4) {
      for (int m = close_mask4(p, i, j, b1, d2); m; m &= m - 1) uf->unite(i, j + __builtin_ctz(m));
    }
  }
}

// True if some point of [a0, a1) is within sqrt(d2) of some point of [b0, b1).
bool any_close(const Positions& p, uint32_t a0, uint32_t a1, uint32_t b0, uint32_t b1, simd::F4 d2) {
  for (uint32_t i = a0; i < a1; ++i) {
    for (uint32_t j = b0; j < b1; j += 4) {
      if (close_mask4(p, i, j, b1, d2)) return true;
    }
  }
  return false;
}

// Points bucketed into cubic cells, in key order: the cells of one (x, y) column are
// contiguous and sorted by z, so neighbours are found per column pair rather than per cell.
struct Cells {
  std::vector<uint32_t> order;         // input index of each slot
  Positions xyz;                       // position of each slot
  std::vector<uint32_t> begin;         // cell c spans slots [begin[c], begin[c + 1])
  std::vector<uint32_t> z;             // z coordinate of each cell
  std::vector<uint64_t> column;        // (x, y) key of each column
  std::vector<uint32_t> column_begin;  // column k spans cells [column_begin[k], ...[k + 1])
  int y_bits = 0;
  int64_t x_extent = 1, y_extent = 1;
};

// Cell keys of the finite points, sorted, with the points' input indices alongside.
void sorted_keys(const PointCloud& cloud, const GridFrame& f, std::vector<uint64_t>* keys,
                 std::vector<uint32_t>* order) {
  keys->resize(cloud.size());
  size_t n = 0;
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (!is_finite(cloud[i])) continue;
    (*keys)[n++] = f.total_bits <= 32 ? f.fast_key(cloud[i]) << 32 | i : f.fast_key(cloud[i]);
  }
  keys->resize(n);
  order->resize(n);
  if (f.total_bits > 32) {  // does not fit beside the index: the general sort
    for (size_t i = 0, s = 0; i < cloud.size(); ++i) {
      if (is_finite(cloud[i])) (*order)[s++] = static_cast<uint32_t>(i);
    }
    radix_sort(*keys, *order, f.total_bits);
    return;
  }
  sort_packed(*keys, f.total_bits);
  for (size_t s = 0; s < n; ++s) {
    (*order)[s] = static_cast<uint32_t>((*keys)[s]);
    (*keys)[s] >>= 32;
  }
}

// Same cells (and GridFrame::fit() errors) as CellGrid::build(), without its per-point
// cell index and lookup table, which clustering does not need.
Cells bucket_points(const PointCloud& cloud, float cell_m) {
  const GridFrame f = GridFrame::fit(cloud, cell_m, false, "SegmenterConfig.cluster_distance_m");
  Cells g;
  std::vector<uint64_t> keys;
  sorted_keys(cloud, f, &keys, &g.order);
  const uint64_t z_mask = (uint64_t{1} << f.bits[2]) - 1;
  g.xyz.resize(keys.size());
  for (size_t s = 0; s < keys.size(); ++s) {
    const Point& pt = cloud[g.order[s]];
    g.xyz.x[s] = pt.x;
    g.xyz.y[s] = pt.y;
    g.xyz.z[s] = pt.z;
    if (s > 0 && keys[s] == keys[s - 1]) continue;
    if (s == 0 || (keys[s] >> f.bits[2]) != (keys[s - 1] >> f.bits[2])) {
      g.column.push_back(keys[s] >> f.bits[2]);
      g.column_begin.push_back(static_cast<uint32_t>(g.z.size()));
    }
    g.begin.push_back(static_cast<uint32_t>(s));
    g.z.push_back(static_cast<uint32_t>(keys[s] & z_mask));
  }
  g.begin.push_back(static_cast<uint32_t>(keys.size()));
  g.column_begin.push_back(static_cast<uint32_t>(g.z.size()));
  g.y_bits = f.bits[1];
  g.x_extent = f.extent[0];
  g.y_extent = f.extent[1];
  return g;
}

// Calls fn(c, nb) for the cells c of [a0, a1) and nb of [b0, b1) (two columns) whose z
// differs by at most one.
template <typename Fn>
void for_each_pair_in_columns(const std::vector<uint32_t>& z, uint32_t a0, uint32_t a1, uint32_t b0, uint32_t b1,
                              Fn& fn) {
  for (uint32_t c = a0; c < a1 && b0 < b1; ++c) {
    while (b0 < b1 && z[b0] + 1 < z[c]) ++b0;
    for (uint32_t j = b0; j < b1 && z[j] <= z[c] + 1; ++j) fn(c, j);
  }
}

// Calls fn(c, nb) once per pair of adjacent occupied cells (26-neighbourhood): within a
// column, and towards the 4 "forward" columns (0, +1), (+1, -1), (+1, 0), (+1, +1). Columns
// are sorted by key, so one cursor per direction only moves forward.
template <typename Fn>
void for_each_adjacent_pair(const Cells& g, Fn&& fn) {
  static constexpr int64_t kForward[4][2] = {{0, 1}, {1, -1}, {1, 0}, {1, 1}};
  const uint64_t y_mask = (uint64_t{1} << g.y_bits) - 1;
  const size_t columns = g.column.size();
  size_t cursor[4] = {0, 0, 0, 0};
  for (size_t a = 0; a < columns; ++a) {
    const uint32_t c0 = g.column_begin[a], c1 = g.column_begin[a + 1];
    for (uint32_t c = c0; c + 1 < c1; ++c) {
      if (g.z[c + 1] == g.z[c] + 1) fn(c, c + 1);
    }
    const int64_t x = static_cast<int64_t>(g.column[a] >> g.y_bits);
    const int64_t y = static_cast<int64_t>(g.column[a] & y_mask);
    for (int d = 0; d < 4; ++d) {
      const int64_t nx = x + kForward[d][0], ny = y + kForward[d][1];
      if (nx >= g.x_extent || ny < 0 || ny >= g.y_extent) continue;
      const uint64_t target = (static_cast<uint64_t>(nx) << g.y_bits) | static_cast<uint64_t>(ny);
      size_t& b = cursor[d];
      while (b < columns && g.column[b] < target) ++b;
      if (b == columns || g.column[b] != target) continue;
      for_each_pair_in_columns(g.z, c0, c1, g.column_begin[b], g.column_begin[b + 1], fn);
    }
  }
}

// Links the points of a cell of at most 32 points through adjacency bit masks, without
// union-find traffic: each point's parent becomes the first point of its component (the
// component's smallest slot, as unite() would choose). Returns true if that is one component.
bool link_small_cell(const Positions& p, uint32_t a0, uint32_t n, simd::F4 d2, UnionFind* uf) {
  uint32_t adj[32];  // the distance is symmetric, so row i is also column i
  for (uint32_t i = 0; i < n; ++i) {
    adj[i] = 0;
    for (uint32_t j = 0; j < n; j += 4) {
      adj[i] |= static_cast<uint32_t>(close_mask4(p, a0 + i, a0 + j, a0 + n, d2)) << j;
    }
  }
  const uint32_t all = n == 32 ? ~0u : (1u << n) - 1;
  uint32_t left = all;
  while (left) {
    const int seed = __builtin_ctz(left);
    uint32_t comp = adj[seed], done = 1u << seed;
    while (comp != done) {
      const int k = __builtin_ctz(comp & ~done);
      done |= 1u << k;
      comp |= adj[k];
    }
    for (uint32_t m = comp; m; m &= m - 1) uf->set_parent(a0 + __builtin_ctz(m), a0 + seed);
    if (comp == all) return true;
    left &= ~comp;
  }
  return false;
}

// Bounding box of a cell's points as (x, y, z, 0) lanes.
struct CellBox {
  simd::F4 lo, hi;
};

// Squared distance between two boxes, summed in close_mask4()'s order: no pair of points of the
// boxes is closer, also after rounding, so a pair skipped on this is never a close pair.
float box_gap2(const CellBox& a, const CellBox& b) {
  const simd::F4 gap = simd::max(simd::max(b.lo - a.hi, a.lo - b.hi), simd::zero());
  float sq[4];
  simd::store(sq, gap * gap);
  return sq[0] + (sq[1] + sq[2]);
}

// Links the points within each cell; returns the cells' boxes and whether each cell is
// already one component.
std::vector<CellBox> link_cells(const Cells& g, float d2, UnionFind* uf, std::vector<uint8_t>* connected) {
  const simd::F4 d2x4 = simd::splat(d2);
  const uint32_t cells = static_cast<uint32_t>(g.z.size());
  std::vector<CellBox> boxes(cells);
  connected->resize(cells);
  const Positions& p = g.xyz;
  for (uint32_t c = 0; c < cells; ++c) {
    const uint32_t a0 = g.begin[c], a1 = g.begin[c + 1];
    simd::F4 lo = simd::make(p.x[a0], p.y[a0], p.z[a0], 0.f), hi = lo;
    for (uint32_t i = a0 + 1; i < a1; ++i) {
      const simd::F4 v = simd::make(p.x[i], p.y[i], p.z[i], 0.f);
      lo = simd::min(lo, v);
      hi = simd::max(hi, v);
    }
    boxes[c] = {lo, hi};
    if (a1 - a0 <= 32) {
      (*connected)[c] = link_small_cell(p, a0, a1 - a0, d2x4, uf);
      continue;
    }
    link_ranges(p, a0, a1, a0, a1, d2x4, true, uf);
    bool one = true;
    for (uint32_t i = a0 + 1; i < a1; ++i) one = one && uf->find(i) == uf->find(a0);
    (*connected)[c] = one;
  }
  return boxes;
}
}  // namespace

Clusters collect_clusters(const std::vector<uint32_t>& order, std::vector<uint32_t> root,
                          const SegmenterConfig& config) {
  const size_t n = order.size();
  std::vector<uint32_t> size(n, 0);
  for (size_t k = 0; k < n; ++k) ++size[root[k]];
  // Walking the input indices in increasing order yields sorted members and clusters ordered
  // by their smallest index, without sorting.
  uint32_t end = 0;
  for (uint32_t i : order) end = std::max(end, i + 1);
  std::vector<uint32_t> group(end, FlatHashMap::kMissing), slot(n, FlatHashMap::kMissing);
  for (size_t k = 0; k < n; ++k) group[order[k]] = root[k];
  Clusters clusters;
  for (uint32_t i = 0; i < end; ++i) {
    const uint32_t r = group[i];
    if (r == FlatHashMap::kMissing || static_cast<int>(size[r]) < config.min_points ||
        static_cast<int>(size[r]) > config.max_points) {
      continue;
    }
    if (slot[r] == FlatHashMap::kMissing) {
      slot[r] = static_cast<uint32_t>(clusters.size());
      clusters.emplace_back();
      clusters.back().reserve(size[r]);
    }
    clusters[slot[r]].push_back(i);
  }
  return clusters;
}

// Components only need one close pair per pair of components, so after each cell has been
// linked internally, a neighbour cell pair is skipped when the boxes are too far apart or both
// cells already lie in one component, and otherwise searched only until the first close pair.
// Nearly all pairs of a surface take the shortcut.
Clusters euclidean_clusters(const PointCloud& cloud, const SegmenterConfig& config) {
  const Cells g = bucket_points(cloud, config.cluster_distance_m);
  const float d2 = config.cluster_distance_m * config.cluster_distance_m;
  UnionFind uf(g.order.size());
  std::vector<uint8_t> connected;
  const std::vector<CellBox> boxes = link_cells(g, d2, &uf, &connected);
  const simd::F4 d2x4 = simd::splat(d2);
  for_each_adjacent_pair(g, [&](uint32_t c, uint32_t nb) {
    if (box_gap2(boxes[c], boxes[nb]) > d2) return;
    const uint32_t a0 = g.begin[c], a1 = g.begin[c + 1];
    const uint32_t b0 = g.begin[nb], b1 = g.begin[nb + 1];
    if (connected[c] && connected[nb]) {
      if (uf.find(a0) != uf.find(b0) && any_close(g.xyz, a0, a1, b0, b1, d2x4)) uf.unite(a0, b0);
    } else {
      link_ranges(g.xyz, a0, a1, b0, b1, d2x4, false, &uf);
    }
  });
  std::vector<uint32_t> root(g.order.size());
  for (uint32_t k = 0; k < root.size(); ++k) root[k] = uf.find(k);
  return collect_clusters(g.order, std::move(root), config);
}

}  // namespace detail

void SegmenterConfig::validate() const {
  const auto positive = [](float v, const char* field) {
    if (!(v > 0.0f) || !std::isfinite(v)) {
      throw std::invalid_argument(std::string("SegmenterConfig.") + field + " must be positive");
    }
  };
  positive(cluster_distance_m, "cluster_distance_m");
  if (min_points < 1) throw std::invalid_argument("SegmenterConfig.min_points must be >= 1");
  if (max_points < min_points) {
    throw std::invalid_argument("SegmenterConfig.max_points must be >= min_points");
  }
  positive(normal_radius_m, "normal_radius_m");
  if (!(max_normal_angle_deg >= 0.0f && max_normal_angle_deg <= 180.0f)) {
    throw std::invalid_argument("SegmenterConfig.max_normal_angle_deg must be in [0, 180]");
  }
  if (!(max_curvature >= 0.0f) || !std::isfinite(max_curvature)) {
    throw std::invalid_argument("SegmenterConfig.max_curvature must be >= 0");
  }
  if (min_normal_neighbours < 3) {
    throw std::invalid_argument("SegmenterConfig.min_normal_neighbours must be >= 3");
  }
  if (!(range_image_beta_deg > 0.0f && range_image_beta_deg < 90.0f)) {
    throw std::invalid_argument("SegmenterConfig.range_image_beta_deg must be in (0, 90)");
  }
  if (range_image_rows < 0 || range_image_rows > 1024) {
    throw std::invalid_argument("SegmenterConfig.range_image_rows must be in 0..1024 (0: the sensor's rings)");
  }
  if (!(range_image_azimuth_step_deg == 0.0f ||
        (range_image_azimuth_step_deg >= 0.05f && range_image_azimuth_step_deg <= 10.0f))) {
    throw std::invalid_argument("SegmenterConfig.range_image_azimuth_step_deg must be 0 (measured) or in [0.05, 10]");
  }
}

Segments segment_cloud(const PointCloud& cloud, const SegmenterConfig& config, const std::vector<uint32_t>* labels) {
  config.validate();
  if (labels && labels->size() != cloud.size()) {
    throw std::invalid_argument("segment_cloud: labels size differs from cloud size");
  }
  if (cloud.empty()) return {};
  detail::Clusters clusters;
  switch (config.type) {
    case SegmenterType::kEuclidean:
    case SegmenterType::kRangeImage:  // no scan structure here (segmenter.h)
      clusters = detail::euclidean_clusters(cloud, config);
      break;
    case SegmenterType::kRegionGrowing: clusters = detail::region_growing_clusters(cloud, config); break;
    default: throw std::invalid_argument("SegmenterConfig.type is not a known SegmenterType");
  }
  return detail::build_segments(cloud, clusters, labels);
}

Segments detail::build_segments(const PointCloud& cloud, const Clusters& clusters,
                                const std::vector<uint32_t>* labels) {
  Segments segments(clusters.size());
  std::vector<uint32_t> scratch;
  for (size_t s = 0; s < clusters.size(); ++s) {
    Segment& seg = segments[s];
    seg.id = s;
    seg.points.reserve(clusters[s].size());
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (uint32_t i : clusters[s]) {
      seg.points.push_back(cloud[i]);
      sum += cloud[i].xyz().cast<double>();
    }
    seg.centroid = (sum / double(clusters[s].size())).cast<float>();
    if (labels) {
      seg.label = detail::majority_label(*labels, clusters[s].data(), clusters[s].size(), &scratch);
    }
  }
  return segments;
}

}  // namespace segmatch
