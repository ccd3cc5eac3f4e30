// Building a segment map from a mapping traversal (paper III-A and IV-A): scans are
// accumulated into a local cloud, and every map_every_m of driving the cylinder around the
// vehicle is segmented and described; the segments (world frame) go into a SegmentMap, which
// keeps one segment per object, its most complete view. Knows no files: the caller reads the
// scans and writes the map.
#pragma once

#include "segmatch/core/local_cloud.h"
#include "segmatch/core/localizer.h"
#include "segmatch/core/segment_map.h"

#include <cstdint>
#include <vector>

namespace segmatch {

struct MapBuilderConfig {
  LocalCloudConfig local_cloud;
  SegmentationConfig segmentation;
  SegmentMapConfig segment_map;
  // Distance driven (sum of the steps between consecutive scans) between two segmented local
  // clouds. 5 m sees every object from about a dozen positions inside the 60 m cylinder, so the
  // map keeps a near-complete view of each, while segmenting only one scan position in ~50 at
  // 10 m/s and 10 Hz (segmentation dominates the cost).
  double map_every_m = 5.0;
  void validate() const;  // throws std::invalid_argument naming the field
};

// Wall-clock time summed over the whole build, per stage (milliseconds).
struct MapBuilderTimings {
  double accumulate_ms = 0;  // LocalCloud::add_scan
  double crop_ms = 0;        // cylinder extraction
  double voxel_ms = 0, ground_ms = 0, segment_ms = 0, describe_ms = 0;  // extract_segments
  double merge_ms = 0;       // SegmentMap::add
  double total_ms() const {
    return accumulate_ms + crop_ms + voxel_ms + ground_ms + segment_ms + describe_ms + merge_ms;
  }
};

class MapBuilder {
 public:
  explicit MapBuilder(const MapBuilderConfig& config = {});

  // Adds one scan (points in the sensor frame, taken at T_world_sensor; optional per-point
  // SemanticKITTI labels). When the vehicle drove map_every_m since the last segmented local
  // cloud (or since the first scan), the local cloud is cropped around T_world_sensor,
  // segmented and merged into the map, its segments attributed to keyframe scan_index.
  // Returns whether a local cloud was segmented.
  bool add_scan(const PointCloud& points_sensor, const Pose3d& T_world_sensor, uint32_t scan_index,
                const std::vector<uint32_t>* labels = nullptr);
  // Segments the local cloud at the last scan if the vehicle moved since the last segmented
  // one, so that the objects of the final stretch reach the map. Returns whether it did.
  bool finish();

  // The map: one segment per object, world frame, with descriptors. SegmentMap merges a view
  // into the nearest segment, but a merge moves that segment's centroid and can bring it
  // within duplicate_distance_m of another view of the same object; these are resolved here
  // (the view with more points is kept), lazily, so call after the last add_scan / finish.
  // Not thread-safe (the result is cached).
  const Segments& segments() const;
  // For each segment, the scan index of the local cloud its kept view came from.
  const std::vector<uint32_t>& keyframe_of_segment() const;
  size_t local_clouds() const { return local_clouds_; }
  // Segments extracted from all local clouds before merging (>= segments().size()).
  size_t extracted_segments() const { return extracted_segments_; }
  double distance_driven_m() const { return odometer_m_; }
  const MapBuilderTimings& timings() const { return timings_; }
  const MapBuilderConfig& config() const { return config_; }

 private:
  void segment_local_cloud();
  void consolidate() const;

  MapBuilderConfig config_;
  LocalCloud local_;
  SegmentMap map_;
  std::vector<uint32_t> keyframe_of_segment_;
  std::vector<size_t> points_of_segment_;  // to see which segments a merge replaced
  mutable Segments segments_;                 // consolidated map (see segments())
  mutable std::vector<uint32_t> keyframes_;  // of segments_
  mutable bool consolidated_ = false;
  MapBuilderTimings timings_;
  size_t local_clouds_ = 0, extracted_segments_ = 0;
  bool has_scan_ = false, has_labels_ = false;
  Pose3d T_world_last_ = Pose3d::Identity();
  uint32_t last_index_ = 0;
  double odometer_m_ = 0.0, segmented_at_m_ = 0.0;
};

}  // namespace segmatch
