#include "segmatch/core/verification/support.h"
#include "detail/seg_grid.h"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace segmatch {

CentroidIndex::CentroidIndex(const Segments& segments, float cell_m) : cell_m_(cell_m) {
  if (!(cell_m > 0.f) || !std::isfinite(cell_m))
    throw std::invalid_argument("CentroidIndex: cell_m must be finite and > 0");
  centroids_.reserve(segments.size());
  cells_.reserve(segments.size());
  for (size_t i = 0; i < segments.size(); ++i) {
    const Eigen::Vector3f& c = segments[i].centroid;
    centroids_.push_back(c);
    cells_.emplace(key(static_cast<int>(std::floor(c.x() / cell_m_)), static_cast<int>(std::floor(c.y() / cell_m_)),
                       static_cast<int>(std::floor(c.z() / cell_m_))),
                   static_cast<int>(i));
  }
}

uint64_t CentroidIndex::key(int x, int y, int z) const {
  return detail::pack21(x, y, z);  // +-1e6 cells, far beyond any map
}

int CentroidIndex::nearest_within(const Eigen::Vector3f& p, float radius_m) const {
  if (!p.allFinite()) return -1;
  const int cx = static_cast<int>(std::floor(p.x() / cell_m_));
  const int cy = static_cast<int>(std::floor(p.y() / cell_m_));
  const int cz = static_cast<int>(std::floor(p.z() / cell_m_));
  const int reach = static_cast<int>(std::ceil(radius_m / cell_m_));
  int best = -1;
  float best_sq = radius_m * radius_m;
  for (int dx = -reach; dx <= reach; ++dx)
    for (int dy = -reach; dy <= reach; ++dy)
      for (int dz = -reach; dz <= reach; ++dz) {
        const auto range = cells_.equal_range(key(cx + dx, cy + dy, cz + dz));
        for (auto it = range.first; it != range.second; ++it) {
          const float sq = (centroids_[it->second] - p).squaredNorm();
          if (sq <= best_sq) best_sq = sq, best = it->second;
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
