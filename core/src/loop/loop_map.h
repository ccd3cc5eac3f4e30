// The growing target map of the loop detector (loop_closure.h): segments in the odometry
// frame with when and from which local cloud they were last seen. Views of one object are
// merged as in SegmentMap (the view with more points wins, the object keeps its id), but a
// new view merges only with a segment that is still recent; old segments are frozen so a
// revisit with drifted odometry never fuses with, or refreshes, the view it should match.
#pragma once

#include "segmatch/core/detail/centroid_grid.h"
#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/segmentation/segment.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace segmatch {

// When (odometer, time) and from which local cloud (frame) a map segment was last seen.
struct Sighting {
  size_t frame = 0;
  double odometer_m = 0;
  double time_s = 0;
};

// Recent-past window: a sighting is recent if less than distance_m was driven since, or less
// than time_s elapsed.
struct RecencyWindow {
  double distance_m = 150.0;
  double time_s = 0.0;
  bool recent(const Sighting& seen, const Sighting& now) const {
    return now.odometer_m - seen.odometer_m < distance_m || now.time_s - seen.time_s < time_s;
  }
};

class LoopSegmentMap {
 public:
  LoopSegmentMap(const SegmentMapConfig& config, const RecencyWindow& window);

  // Adds the segments of one local cloud seen at `now`. Each merges with the nearest recent
  // segment within duplicate_distance_m (refreshing its sighting, and replacing its points if
  // it has more), or is added as a new object. Returns how many were new.
  size_t add(Segments segments, const Sighting& now);

  // Indices of the segments that are not recent at `now`, in insertion order.
  std::vector<int> eligible(const Sighting& now) const;

  const Segments& segments() const { return segments_; }
  const std::vector<Sighting>& sightings() const { return sightings_; }
  // The local cloud each segment's points come from (its kept view). Not the last sighting: a
  // sighting that keeps the old, larger view leaves the points, and so the odometry drift
  // they carry, those of the earlier frame.
  const std::vector<size_t>& view_frames() const { return view_frames_; }
  size_t size() const { return segments_.size(); }

 private:
  int find_recent_duplicate(const Eigen::Vector3f& centroid, const Sighting& now) const;
  void refile(int index, const Eigen::Vector3f& old_centroid);

  SegmentMapConfig config_;
  RecencyWindow window_;
  Segments segments_;
  std::vector<Sighting> sightings_;  // parallel to segments_
  std::vector<size_t> view_frames_;  // parallel to segments_
  CentroidGrid grid_;                // segment centroids -> indices
  uint64_t next_id_ = 0;
};

}  // namespace segmatch
