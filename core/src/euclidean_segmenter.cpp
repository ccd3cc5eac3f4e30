// Euclidean clustering of occupied voxels (paper III-A, IV-A: distance 0.2 m, segments of
// 100 .. 15000 points) and the segment_cloud() dispatch.
//
// Points are bucketed into cubic cells of edge cluster_distance_m, so every neighbour of a
// point lies in its own or one of the 26 adjacent cells (found by a sweep, no hashing).
// Each cell pair is visited once and close pairs are merged with union-find; no search tree.
#include <algorithm>
#include <stdexcept>
#include <string>

#include "seg_grid.h"
#include "seg_segmenters.h"

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

// Merges the close pairs between the grid-order ranges [a0, a1) and [b0, b1).
void link_ranges(const std::vector<Eigen::Vector3f>& xyz, uint32_t a0, uint32_t a1, uint32_t b0,
                 uint32_t b1, float d2, bool same, UnionFind* uf) {
  for (uint32_t i = a0; i < a1; ++i) {
    for (uint32_t j = same ? i + 1 : b0; j < b1; ++j) {
      if ((xyz[i] - xyz[j]).squaredNorm() <= d2) uf->unite(i, j);
    }
  }
}

// True if some point of [a0, a1) is within sqrt(d2) of some point of [b0, b1).
bool any_close(const std::vector<Eigen::Vector3f>& xyz, uint32_t a0, uint32_t a1, uint32_t b0,
               uint32_t b1, float d2) {
  for (uint32_t i = a0; i < a1; ++i) {
    for (uint32_t j = b0; j < b1; ++j) {
      if ((xyz[i] - xyz[j]).squaredNorm() <= d2) return true;
    }
  }
  return false;
}

// Per cell: bounding box of its points and whether they already form one component.
struct CellInfo {
  Eigen::Vector3f lo, hi;
  bool connected;
};

float box_gap2(const CellInfo& a, const CellInfo& b) {
  const Eigen::Vector3f gap = (b.lo - a.hi).cwiseMax(a.lo - b.hi).cwiseMax(0.f);
  return gap.squaredNorm();
}

// Calls fn(c, nb) once per pair of adjacent occupied cells (26-neighbourhood), nb after c in
// key order: the 13 "forward" neighbours lie in the columns (0, 0) (dz = +1 only), (0, +1),
// (+1, -1), (+1, 0) and (+1, +1) (dz = -1..1). Cells are sorted by key, so one cursor per
// column only moves forward: no table, no hashing.
template <typename Fn>
void for_each_forward_pair(const CellGrid& grid, Fn&& fn) {
  static constexpr int64_t kColumns[5][2] = {{0, 0}, {0, 1}, {1, -1}, {1, 0}, {1, 1}};
  const GridFrame& f = grid.frame;
  const uint32_t n = static_cast<uint32_t>(grid.cell_count());
  uint32_t cursor[5] = {0, 0, 0, 0, 0};
  for (uint32_t c = 0; c < n; ++c) {
    int64_t x, y, z;
    grid.cell_coords(c, &x, &y, &z);
    for (int col = 0; col < 5; ++col) {
      const int64_t nx = x + kColumns[col][0], ny = y + kColumns[col][1];
      const int64_t z0 = col == 0 ? z + 1 : std::max<int64_t>(z - 1, 0);
      const int64_t z1 = std::min<int64_t>(z + 1, f.extent[2] - 1);
      if (!f.inside(nx, ny, 0) || z0 > z1) continue;
      const uint64_t first = f.pack(nx, ny, z0), last = f.pack(nx, ny, z1);
      uint32_t& k = cursor[col];
      while (k < n && grid.cell_key[k] < first) ++k;
      for (uint32_t j = k; j < n && grid.cell_key[j] <= last; ++j) fn(c, j);
    }
  }
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
  const CellGrid grid = CellGrid::build(cloud, config.cluster_distance_m, false,
                                        "SegmenterConfig.cluster_distance_m", false);
  std::vector<Eigen::Vector3f> xyz(grid.order.size());
  for (size_t k = 0; k < grid.order.size(); ++k) xyz[k] = cloud[grid.order[k]].xyz();
  const float d2 = config.cluster_distance_m * config.cluster_distance_m;
  UnionFind uf(grid.order.size());
  std::vector<CellInfo> info(grid.cell_count());
  for (uint32_t c = 0; c < grid.cell_count(); ++c) {
    const uint32_t a0 = grid.begin[c], a1 = grid.begin[c + 1];
    link_ranges(xyz, a0, a1, a0, a1, d2, true, &uf);
    CellInfo& ci = info[c];
    ci.lo = ci.hi = xyz[a0];
    ci.connected = true;
    for (uint32_t i = a0 + 1; i < a1; ++i) {
      ci.lo = ci.lo.cwiseMin(xyz[i]);
      ci.hi = ci.hi.cwiseMax(xyz[i]);
      ci.connected = ci.connected && uf.find(i) == uf.find(a0);
    }
  }
  for_each_forward_pair(grid, [&](uint32_t c, uint32_t nb) {
    if (box_gap2(info[c], info[nb]) > d2) return;
    const uint32_t a0 = grid.begin[c], a1 = grid.begin[c + 1];
    const uint32_t b0 = grid.begin[nb], b1 = grid.begin[nb + 1];
    if (info[c].connected && info[nb].connected) {
      if (uf.find(a0) != uf.find(b0) && any_close(xyz, a0, a1, b0, b1, d2)) uf.unite(a0, b0);
    } else {
      link_ranges(xyz, a0, a1, b0, b1, d2, false, &uf);
    }
  });
  std::vector<uint32_t> root(grid.order.size());
  for (uint32_t k = 0; k < root.size(); ++k) root[k] = uf.find(k);
  return collect_clusters(grid.order, std::move(root), config);
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
}

Segments segment_cloud(const PointCloud& cloud, const SegmenterConfig& config,
                       const std::vector<uint32_t>* labels) {
  config.validate();
  if (labels && labels->size() != cloud.size()) {
    throw std::invalid_argument("segment_cloud: labels size differs from cloud size");
  }
  if (cloud.empty()) return {};
  detail::Clusters clusters;
  switch (config.type) {
    case SegmenterType::kEuclidean:
      clusters = detail::euclidean_clusters(cloud, config);
      break;
    case SegmenterType::kRegionGrowing:
      clusters = detail::region_growing_clusters(cloud, config);
      break;
    default:
      throw std::invalid_argument("SegmenterConfig.type is not a known SegmenterType");
  }
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
