// Local clouds along a simulated traversal, as a vehicle builds them (paper III-A): scans
// accumulated in the world frame, one every metre travelled, cropped to a cylinder.
#pragma once

#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/traversal.h"

#include <functional>

namespace segmatch::sim {

struct SimulatedLocalCloud {
  size_t frame = 0;              // traversal scan index at which the cloud was taken
  Pose3d T_world_sensor;         // sensor pose at that scan (the truth)
  Pose3d T_cloud_sensor;         // the sensor in the cloud's frame: T_world_sensor, or the
                                 // schedule's odometry pose
  PointCloud cloud;              // world frame (voxels for for_each_voxelized_cloud)
  std::vector<uint32_t> labels;  // per point (voxel), SemanticKITTI
};

struct LocalCloudSchedule {
  double every_m = 10.0;   // one local cloud each time the vehicle drove this far
  double warmup_m = 30.0;  // first local cloud only after this much accumulation
  size_t first_frame = 0, last_frame = SIZE_MAX;
  int threads = 0;    // scan simulation threads (0: one per core)
  uint64_t seed = 1;  // noise seed of the scans
  // The vehicle's odometry, one pose per traversal scan (e.g. drifted_odometry of the
  // traversal's poses): scans are cast at the true poses but accumulated and cropped at these,
  // and `cloud` is in the odometry's frame. Null: the true poses (world frame).
  const Poses* odometry = nullptr;
};

// Simulates the scans a local cloud keeps (the first, then one per min_travel_between_scans_m,
// within the schedule's frames) and calls `visit(frame, scan)` for each, in order. Scans are
// simulated in parallel batches; visits are sequential.
void for_each_kept_scan(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                        const LocalCloudConfig& local_config, const LocalCloudSchedule& schedule,
                        const std::function<void(size_t, const SimulatedScan&)>& visit);

// Simulates the scans the local cloud keeps and calls `visit` for each scheduled local
// cloud, in order. Scans are simulated in parallel; accumulation is sequential.
void for_each_local_cloud(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                          const LocalCloudConfig& local_config, const LocalCloudSchedule& schedule,
                          const std::function<void(const SimulatedLocalCloud&)>& visit);

// The same with the local cloud kept voxelized as the map builder and a vehicle keep it
// (VoxelAccumulator): `cloud` is voxel_filter(crop) with `voxel` and `labels` each voxel's
// majority label, for extract_segments_from_voxels or CloudKind::kVoxelized. Equal to
// voxel_filter of for_each_local_cloud's clouds up to the rounding of the centroid sums, and
// it does not crop and voxelize millions of points at every cloud (the end-to-end tests' time
// went mostly there).
void for_each_voxelized_cloud(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                              const LocalCloudConfig& local_config, const VoxelGridConfig& voxel,
                              const LocalCloudSchedule& schedule,
                              const std::function<void(const SimulatedLocalCloud&)>& visit);

}  // namespace segmatch::sim
