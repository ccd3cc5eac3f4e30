// Evidence for a pose hypothesis beyond its matches (beyond the paper). Verification on
// centroids (paper III-E) accepts the largest consistent cluster of matches; in streets with
// evenly spaced poles, trees or windows a shifted copy of the true cluster is consistent too.
// Under the true pose, however, most query segments land on a map segment, not only the
// matched ones; under a shifted pose only the repeated objects do. The support of a hypothesis
// is the number of query segments whose transformed centroid has a map centroid nearby.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/core/segmentation/segment.h"

#include <cstdint>
#include <memory>
#include <vector>

namespace segmatch {

namespace detail {
struct CellGrid;
}

// Hash grid over segment centroids for fixed-radius nearest queries: the core's one cell grid
// (detail::CellGrid, cells in a flat hash table), shared by copies.
class CentroidIndex {
 public:
  CentroidIndex() = default;
  // cell_m: grid cell edge, at least the largest radius later queried.
  CentroidIndex(const Segments& segments, float cell_m);
  // Index of the segment whose centroid is nearest to p within radius_m, or -1. Of centroids
  // at the same distance, the one met last (neighbour cells in a fixed order, a cell's
  // segments by index).
  int nearest_within(const Eigen::Vector3f& p, float radius_m) const;
  size_t size() const { return centroids_.size(); }

 private:
  std::vector<Eigen::Vector3f> centroids_;
  std::shared_ptr<const detail::CellGrid> grid_;
};

struct Support {
  Matches pairs;  // query segment -> map segment within the radius (one per query segment)
  size_t count() const { return pairs.size(); }
};

// Query segments (query frame) that, moved by T_map_query, have a map centroid within radius_m.
Support support_of(const Segments& query, const CentroidIndex& map, const Pose3d& T_map_query, float radius_m);

}  // namespace segmatch
