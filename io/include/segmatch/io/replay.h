// Replays a recorded sequence as a vehicle would (paper III-A): its scans, placed with the
// sequence's own poses re-expressed in an odometry frame that starts at the first used scan,
// are accumulated into a local cloud; every `every_m` of driving the cylinder around the
// sensor is handed to the caller as a query. The vehicle's odometry frame is not the map's:
// finding T_map_odom is the localizer's job.
#pragma once

#include <segmatch/core/localization/local_cloud.h>
#include <segmatch/core/preprocess/preprocess.h>
#include <segmatch/io/sequence.h>

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>

namespace segmatch {
namespace io {

struct ReplayConfig {
  double every_m = 10.0;   // distance driven between two queries
  double warmup_m = 30.0;  // no query before this much driving (the local cloud is too thin)
  size_t first = 0;        // first scan used
  size_t last = SIZE_MAX;  // last scan used (inclusive; clipped to the sequence)
  size_t stride = 1;       // use every stride-th scan
  LocalCloudConfig local_cloud;
  // Hand out the voxelized cylinder (VoxelAccumulator with this grid, which must be the map's)
  // instead of raw points: a vehicle sends a few hundred thousand voxel centroids rather than
  // millions of points (docs/protocol.md 5.4, flag bit 1).
  bool voxelize = true;
  VoxelGridConfig voxel;
  // Each query also carries the scans of the last newest_m of driving (0: none), each thinned
  // to one point per newest_leaf_m voxel: the server refines its answer to them, the sensor's
  // pose now (docs/protocol.md 5.4, flag bit 5).
  double newest_m = 10.0;
  float newest_leaf_m = 0.2f;
  // Cold start: every query is one raw scan alone (no accumulation, no warm-up), as a vehicle
  // that has just woken up has; its newest scans are that scan, thinned.
  bool single_scan = false;
  void validate() const;  // throws std::invalid_argument naming the field
};

struct ReplayQuery {
  size_t frame = 0;         // scan index in the sequence
  double odometer_m = 0.0;  // distance driven since the first used scan
  Pose3d T_odom_sensor = Pose3d::Identity();
  Pose3d T_world_sensor = Pose3d::Identity();  // the sequence's own pose of that scan
  PointCloud cloud_odom;                       // the local cylinder, odometry frame
  bool voxelized = false;                      // cloud_odom holds voxel centroids (config.voxelize)
  PointCloud newest_odom;                      // the scans of the last newest_m, thinned (odometry frame)
};

// Which poses put a replayed query's scans into its local cloud. A vehicle has only its own
// odometry; the sequence's reference poses (poses.txt) build clouds no vehicle could, which
// flatters every figure, and serve only to compare.
enum class CloudPoses { kOdometry, kReference };
const char* to_string(CloudPoses poses);
// Parses "odometry" / "reference"; throws std::invalid_argument naming the value otherwise.
CloudPoses parse_cloud_poses(const std::string& name);

// The odometry a replay of `folder` builds its local clouds with: `explicit_path` when given
// (it must exist), else folder/odom_poses.txt. Throws IoError naming what is missing and the
// way out (--odometry FILE, or --cloud-poses reference to compare) when there is none.
std::string odometry_poses_path(const std::string& folder, const std::string& explicit_path);

// Calls visit(query) for every query in order; visit returns false to stop early. progress
// (optional) gets (scans done, scans total). Throws IoError on an unreadable scan.
void replay_sequence(const Sequence& sequence, const ReplayConfig& config,
                     const std::function<bool(const ReplayQuery&)>& visit,
                     const std::function<void(size_t, size_t)>& progress = {});

}  // namespace io
}  // namespace segmatch
