// Region growing with a smoothness constraint (Rabbani et al. 2006), the alternative
// segmenter of paper III-A ("future advances in 3D segmentation ... can be used by replacing
// the respective components"). Like Euclidean clustering it joins points closer than
// cluster_distance_m, but only if their normals agree, so touching surfaces with different
// orientation (a slab against a wall) become separate segments.
//
//   1. normal + curvature of every point from the covariance of its normal_radius_m ball;
//   2. seeds in increasing curvature (flattest first, index breaks ties);
//   3. a region takes neighbours whose normal is within max_normal_angle_deg of the
//      current point's; only those with curvature < max_curvature continue the growth.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <deque>

#include "detail/seg_grid.h"
#include "segmentation/seg_segmenters.h"

namespace segmatch {
namespace detail {
namespace {

struct SurfaceInfo {
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();
  float curvature = 1.0f;  // worse than any real value: sorts last
  bool valid = false;
};

// Points bucketed in cells no smaller than the query radius, with their neighbour cells.
struct NeighbourGrid {
  CellGrid grid;
  std::vector<uint32_t> neighbours;
  NeighbourGrid(const PointCloud& cloud, float cell_m, const char* field)
      : grid(CellGrid::build(cloud, cell_m, false, field, false)), neighbours(neighbour_table(grid)) {}
};

// Calls fn(j) for every point j within sqrt(radius2) of point i (i itself included).
template <typename Fn>
void for_each_neighbour(const NeighbourGrid& ng, const PointCloud& cloud, uint32_t i, float radius2, Fn&& fn) {
  const Eigen::Vector3f p = cloud[i].xyz();
  const uint32_t* cells = &ng.neighbours[size_t(ng.grid.point_cell[i]) * kNeighbourCells];
  for (int o = 0; o < kNeighbourCells; ++o) {
    const uint32_t c = cells[o];
    if (c == FlatHashMap::kMissing) continue;
    for (uint32_t k = ng.grid.begin[c]; k < ng.grid.begin[c + 1]; ++k) {
      const uint32_t j = ng.grid.order[k];
      if ((cloud[j].xyz() - p).squaredNorm() <= radius2) fn(j);
    }
  }
}

SurfaceInfo surface_at(const NeighbourGrid& grid, const PointCloud& cloud, uint32_t i, const SegmenterConfig& config) {
  const Eigen::Vector3f p = cloud[i].xyz();
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
  int count = 0;
  const float r2 = config.normal_radius_m * config.normal_radius_m;
  for_each_neighbour(grid, cloud, i, r2, [&](uint32_t j) {
    const Eigen::Vector3d d = (cloud[j].xyz() - p).cast<double>();  // relative: no cancellation
    sum += d;
    sum2 += d * d.transpose();
    ++count;
  });
  SurfaceInfo info;
  if (count < config.min_normal_neighbours) return info;
  const Eigen::Vector3d mean = sum / count;
  const Eigen::Matrix3d cov = sum2 / count - mean * mean.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(cov);
  const Eigen::Vector3d ev = solver.eigenvalues();  // ascending
  const double total = ev.sum();
  info.normal = solver.eigenvectors().col(0).cast<float>();
  info.curvature = total > 0.0 ? float(std::max(0.0, ev(0)) / total) : 0.0f;
  info.valid = info.normal.allFinite();
  return info;
}

}  // namespace

Clusters region_growing_clusters(const PointCloud& cloud, const SegmenterConfig& config) {
  const NeighbourGrid normal_grid(cloud, config.normal_radius_m, "SegmenterConfig.normal_radius_m");
  const NeighbourGrid grid(cloud, config.cluster_distance_m, "SegmenterConfig.cluster_distance_m");
  const std::vector<uint32_t>& finite = normal_grid.grid.order;  // finite points, any order
  std::vector<SurfaceInfo> surface(cloud.size());
  for (uint32_t i : finite) surface[i] = surface_at(normal_grid, cloud, i, config);

  std::vector<uint32_t> seeds(finite.begin(), finite.end());
  std::sort(seeds.begin(), seeds.end(), [&](uint32_t a, uint32_t b) {
    return surface[a].curvature != surface[b].curvature ? surface[a].curvature < surface[b].curvature : a < b;
  });
  const float cos_max = std::cos(config.max_normal_angle_deg * 3.14159265f / 180.0f);
  const float d2 = config.cluster_distance_m * config.cluster_distance_m;
  constexpr uint32_t kNone = FlatHashMap::kMissing;
  std::vector<uint32_t> region(cloud.size(), kNone);
  uint32_t regions = 0;
  std::deque<uint32_t> queue;
  for (uint32_t s : seeds) {
    if (region[s] != kNone) continue;
    region[s] = regions;
    queue.assign(1, s);
    while (!queue.empty()) {
      const uint32_t cur = queue.front();
      queue.pop_front();
      if (!surface[cur].valid) continue;
      const Eigen::Vector3f n = surface[cur].normal;
      for_each_neighbour(grid, cloud, cur, d2, [&](uint32_t j) {
        if (region[j] != kNone || !surface[j].valid) return;
        if (std::abs(n.dot(surface[j].normal)) < cos_max) return;  // smoothness constraint
        region[j] = regions;
        if (surface[j].curvature < config.max_curvature) queue.push_back(j);
      });
    }
    ++regions;
  }
  std::vector<uint32_t> order(finite.begin(), finite.end());
  std::vector<uint32_t> root(order.size());
  for (size_t k = 0; k < order.size(); ++k) root[k] = region[order[k]];
  return collect_clusters(order, std::move(root), config);
}

}  // namespace detail
}  // namespace segmatch
