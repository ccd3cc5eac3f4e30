// A growing map of target segments. The same object is segmented again from every local
// cloud that sees it; the map keeps one segment per object, the most complete view.
#pragma once

#include "segmatch/core/detail/centroid_grid.h"
#include "segmatch/core/segmentation/segment.h"

#include <vector>

namespace segmatch {

struct SegmentMapConfig {
  // Two segments whose centroids are closer than this are views of the same object.
  float duplicate_distance_m = 1.0f;
  // After a replacement moved a segment's centroid, resolve the segments now within
  // duplicate_distance_m of it (keep the one with more points), so that no two segments of
  // the map are closer than that. MapBuilder always turns this on. Off by default: the
  // simulated training maps (sim::labelled_city) and the end-to-end test's map keep their
  // previous contents, which the default classifier and that test's thresholds were tuned on.
  bool resolve_moved_duplicates = false;
  void validate() const;
};

class SegmentMap {
 public:
  explicit SegmentMap(const SegmentMapConfig& config = {});

  // Adds segments (map frame). A segment near an existing one (the nearest within
  // duplicate_distance_m) replaces it when it has more points (keeping the existing id), and
  // is dropped otherwise. New segments get new ids. A replacement moves the centroid, which
  // can land within the duplicate distance of other segments (views of the same object):
  // with resolve_moved_duplicates those are resolved at once, keeping the one with more
  // points (ties: the older, smaller id), so no two segments of the map are ever closer than
  // duplicate_distance_m. Segments stay in id order. Returns how many segments were new.
  size_t add(Segments segments);

  const Segments& segments() const { return segments_; }
  size_t size() const { return segments_.size(); }

 private:
  int find_duplicate(const Eigen::Vector3f& centroid) const;
  // Indices of the segments other than `self` within the duplicate distance of `self`.
  std::vector<int> neighbours_of(int self) const;
  void erase(int index);  // keeps the order and the grid consistent

  SegmentMapConfig config_;
  Segments segments_;
  CentroidGrid grid_;  // segment centroids -> indices
  uint64_t next_id_ = 0;
};

}  // namespace segmatch
