// Building a segment map from a mapping traversal (paper III-A and IV-A): scans are
// accumulated into a local cloud, kept voxelized incrementally (VoxelAccumulator: the same
// voxels as voxel_filter of the cropped cloud, without re-voxelizing millions of points), and
// every map_every_m of driving the cylinder around the vehicle is segmented and described; the segments (world frame)
// go into a SegmentMap, which keeps one segment per object, its most complete view. Knows no files: the caller reads
// the scans and writes the map.
#pragma once

#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/mapping/surface_layer.h"
#include "segmatch/core/preprocess/voxel_accumulator.h"

#include <cstdint>
#include <unordered_map>
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
  SurfaceLayerConfig surfaces;  // the map's surface layer (surface_layer.h), from every scan
  void validate() const;        // throws std::invalid_argument naming the field
};

// Wall-clock time summed over the whole build, per stage (milliseconds).
struct MapBuilderTimings {
  double accumulate_ms = 0;  // VoxelAccumulator::add_scan (the scans' points summed into voxels)
  double crop_ms = 0;        // VoxelAccumulator::crop: the voxelized cylinder
  // voxel_ms stays 0: the voxel grid is maintained by add_scan and crop above.
  double voxel_ms = 0, ground_ms = 0, segment_ms = 0, describe_ms = 0;  // extract_segments_from_voxels
  double merge_ms = 0;                                                  // SegmentMap::add
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

  // The map: one segment per object, world frame, with descriptors (its SegmentMap runs with
  // resolve_moved_duplicates on, whatever config.segment_map says, so no two segments lie
  // within duplicate_distance_m of each other).
  const Segments& segments() const { return map_.segments(); }
  // For each segment, the scan index of the local cloud its kept view came from.
  const std::vector<uint32_t>& keyframe_of_segment() const;
  size_t local_clouds() const { return local_clouds_; }
  // Segments extracted from all local clouds before merging (>= segments().size()).
  size_t extracted_segments() const { return extracted_segments_; }
  double distance_driven_m() const { return odometer_m_; }
  const MapBuilderTimings& timings() const { return timings_; }
  const MapBuilderConfig& config() const { return config_; }
  // The map's surface layer (world frame; empty when config.surfaces is off).
  PointCloud surface_points() const { return surfaces_.points(); }

 private:
  void segment_local_cloud();

  struct View {
    uint32_t keyframe;
    size_t points;  // to see which segments a merge replaced
  };
  MapBuilderConfig config_;
  VoxelAccumulator local_;
  SegmentMap map_;
  SurfaceAccumulator surfaces_;
  std::unordered_map<uint64_t, View> view_of_id_;
  std::vector<uint32_t> keyframe_of_segment_;  // in the map's order
  MapBuilderTimings timings_;
  size_t local_clouds_ = 0, extracted_segments_ = 0;
  bool has_scan_ = false, has_labels_ = false;
  Pose3d T_world_last_ = Pose3d::Identity();
  uint32_t last_index_ = 0;
  double odometer_m_ = 0.0, segmented_at_m_ = 0.0;
};

}  // namespace segmatch
