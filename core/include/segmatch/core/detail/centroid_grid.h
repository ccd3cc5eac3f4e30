// Segment centroids filed in cubic cells of side cell_m: the neighbourhood search behind the
// duplicate merge of the map builders (paper III-E: "segments whose centroids are closer than a
// threshold are considered duplicates"). SegmentMap and the loop detector's LoopSegmentMap both
// use it; each keeps its own rule for which entries may merge.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <unordered_map>

namespace segmatch {

class CentroidGrid {
 public:
  explicit CentroidGrid(float cell_m) : cell_m_(cell_m) {}

  void insert(const Eigen::Vector3f& centroid, int index) { cells_.emplace(cell_of(centroid), index); }
  // Removes the entry `index` filed under `centroid` (its centroid when it was inserted).
  void erase(const Eigen::Vector3f& centroid, int index);
  void clear() { cells_.clear(); }

  // visit(index) for every entry in the 3 x 3 x 3 cells around p, in a fixed order (cells by
  // dx, dy, dz; entries of a cell as the multimap keeps them).
  template <typename Visit>
  void for_each_near(const Eigen::Vector3f& p, Visit&& visit) const {
    const float d = cell_m_;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto range = cells_.equal_range(cell_of(p + Eigen::Vector3f(dx * d, dy * d, dz * d)));
          for (auto it = range.first; it != range.second; ++it) visit(it->second);
        }
  }

  // The admitted entry whose centroid_of(index) is nearest p and closer than cell_m; ties go to
  // the first visited; -1 if none.
  template <typename CentroidOf, typename Admit>
  int nearest(const Eigen::Vector3f& p, CentroidOf&& centroid_of, Admit&& admit) const {
    int best = -1;
    float best_dist = cell_m_;
    for_each_near(p, [&](int index) {
      if (!admit(index)) return;
      const float dist = (centroid_of(index) - p).norm();
      if (dist < best_dist) {
        best_dist = dist;
        best = index;
      }
    });
    return best;
  }

 private:
  uint64_t cell_of(const Eigen::Vector3f& p) const;

  float cell_m_;
  std::unordered_multimap<uint64_t, int> cells_;  // cell key -> index
};

}  // namespace segmatch
