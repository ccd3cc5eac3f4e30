#include "segmatch/core/verification/support.h"
#include "detail/seg_grid.h"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace segmatch {

CentroidIndex::CentroidIndex(const Segments& segments, float cell_m) {
  if (!(cell_m > 0.f) || !std::isfinite(cell_m))
    throw std::invalid_argument("CentroidIndex: cell_m must be finite and > 0");
  PointCloud centroids;
  centroids.reserve(segments.size());
  centroids_.reserve(segments.size());
  for (const Segment& s : segments) {
    centroids_.push_back(s.centroid);
    centroids.push_back(Point{s.centroid.x(), s.centroid.y(), s.centroid.z(), 0.f});
  }
  grid_ = std::make_shared<const detail::CellGrid>(
      detail::CellGrid::build(centroids, cell_m, false, "CentroidIndex cell_m", true));
}

int CentroidIndex::nearest_within(const Eigen::Vector3f& p, float radius_m) const {
  if (!grid_ || !p.allFinite()) return -1;
  const detail::CellGrid& g = *grid_;
  int64_t c[3];
  for (int a = 0; a < 3; ++a) {
    if (!(std::abs(double(p[a]) / g.frame.cell_m) < 1e15)) return -1;  // far outside any map
    c[a] = g.frame.coord(p[a], a);
  }
  const int64_t reach = static_cast<int64_t>(std::ceil(radius_m / g.frame.cell_m));
  int best = -1;
  float best_sq = radius_m * radius_m;
  for (int64_t dx = -reach; dx <= reach; ++dx)
    for (int64_t dy = -reach; dy <= reach; ++dy)
      for (int64_t dz = -reach; dz <= reach; ++dz) {
        const uint32_t cell = g.cell_at(c[0] + dx, c[1] + dy, c[2] + dz);
        if (cell == detail::FlatHashMap::kMissing) continue;
        for (uint32_t k = g.begin[cell]; k < g.begin[cell + 1]; ++k) {
          const uint32_t i = g.order[k];
          const float sq = (centroids_[i] - p).squaredNorm();
          if (sq <= best_sq) best_sq = sq, best = static_cast<int>(i);
        }
      }
  return best;
}

Support support_of(const Segments& query, const CentroidIndex& map, const Pose3d& T_map_query, float radius_m) {
  Support s;
  const Eigen::Isometry3f T = T_map_query.cast<float>();
  for (size_t i = 0; i < query.size(); ++i) {
    const int j = map.nearest_within(T * query[i].centroid, radius_m);
    if (j >= 0) s.pairs.push_back(Match{static_cast<int>(i), j, 1.0f});
  }
  return s;
}

}  // namespace segmatch
