#include "segmatch/core/detail/centroid_grid.h"
#include "detail/seg_grid.h"

#include <cmath>

namespace segmatch {

uint64_t CentroidGrid::cell_of(const Eigen::Vector3f& p) const {
  auto cell = [&](float v) { return static_cast<int64_t>(std::floor(v / cell_m_)); };
  return detail::pack21(cell(p.z()), cell(p.y()), cell(p.x()));  // x in the low bits
}

void CentroidGrid::erase(const Eigen::Vector3f& centroid, int index) {
  auto range = cells_.equal_range(cell_of(centroid));
  for (auto it = range.first; it != range.second; ++it)
    if (it->second == index) {
      cells_.erase(it);
      return;
    }
}

}  // namespace segmatch
