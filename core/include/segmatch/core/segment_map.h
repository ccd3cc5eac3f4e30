// A growing map of target segments. The same object is segmented again from every local
// cloud that sees it; the map keeps one segment per object, the most complete view.
#pragma once

#include "segmatch/core/segment.h"

#include <unordered_map>

namespace segmatch {

struct SegmentMapConfig {
  // Two segments whose centroids are closer than this are views of the same object.
  float duplicate_distance_m = 1.0f;
  void validate() const;
};

class SegmentMap {
 public:
  explicit SegmentMap(const SegmentMapConfig& config = {});

  // Adds segments (map frame). A segment near an existing one replaces it when it has more
  // points (keeping the existing id), and is dropped otherwise. New segments get new ids.
  // Returns how many segments were new.
  size_t add(Segments segments);

  const Segments& segments() const { return segments_; }
  size_t size() const { return segments_.size(); }

 private:
  using CellKey = uint64_t;
  CellKey cell_of(const Eigen::Vector3f& p) const;
  int find_duplicate(const Eigen::Vector3f& centroid) const;

  SegmentMapConfig config_;
  Segments segments_;
  std::unordered_multimap<CellKey, int> grid_;  // centroid cell -> segment index
  uint64_t next_id_ = 0;
};

}  // namespace segmatch
