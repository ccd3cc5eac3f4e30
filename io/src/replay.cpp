#include "segmatch/io/replay.h"

#include "segmatch/core/preprocess/voxel_accumulator.h"
#include "segmatch/io/error.h"

#include <cmath>
#include <deque>
#include <filesystem>
#include <stdexcept>

namespace segmatch {
namespace io {

void ReplayConfig::validate() const {
  if (!(every_m > 0.0) || !std::isfinite(every_m)) throw std::invalid_argument("ReplayConfig.every_m must be > 0");
  if (!(warmup_m >= 0.0) || !std::isfinite(warmup_m)) throw std::invalid_argument("ReplayConfig.warmup_m must be >= 0");
  if (stride == 0) throw std::invalid_argument("ReplayConfig.stride must be >= 1");
  if (last < first) throw std::invalid_argument("ReplayConfig.last must be >= first");
  if (!(newest_m >= 0.0) || !std::isfinite(newest_m)) throw std::invalid_argument("ReplayConfig.newest_m must be >= 0");
  if (!(newest_leaf_m > 0.0f) || !std::isfinite(newest_leaf_m))
    throw std::invalid_argument("ReplayConfig.newest_leaf_m must be > 0");
  local_cloud.validate();
  voxel.validate();
}

namespace {

PointCloud transformed(const PointCloud& scan_sensor, const Pose3d& T_odom_sensor) {
  PointCloud odom = scan_sensor;
  for (Point& p : odom) {
    const Eigen::Vector3d q = T_odom_sensor * Eigen::Vector3d(p.x, p.y, p.z);
    p.x = static_cast<float>(q.x()), p.y = static_cast<float>(q.y()), p.z = static_cast<float>(q.z());
  }
  return odom;
}

PointCloud thinned(const PointCloud& cloud, float leaf_m) {
  VoxelGridConfig grid;
  grid.leaf_m = leaf_m;
  grid.min_points_per_voxel = 1;
  return voxel_filter(cloud, grid);
}

// The scans of the last newest_m of driving, each thinned (odometry frame).
class NewestScans {
 public:
  explicit NewestScans(const ReplayConfig& config) : config_(config) {
    grid_.leaf_m = config.newest_leaf_m;
    grid_.min_points_per_voxel = 1;
  }
  void add(const PointCloud& scan_sensor, const Pose3d& T_odom_sensor, double odometer_m) {
    if (config_.newest_m <= 0.0) return;
    scans_.push_back({odometer_m, transformed(voxel_filter(scan_sensor, grid_), T_odom_sensor)});
    while (scans_.size() > kMaxScans ||
           (!scans_.empty() && scans_.front().first < odometer_m - config_.newest_m - 1e-9))
      scans_.pop_front();
  }
  PointCloud points() const {
    if (scans_.empty()) return {};
    PointCloud all;
    for (const auto& [at_m, scan] : scans_) all.insert(all.end(), scan.begin(), scan.end());
    return voxel_filter(all, grid_);
  }

 private:
  static constexpr size_t kMaxScans = 64;  // a vehicle standing still
  const ReplayConfig& config_;
  VoxelGridConfig grid_;
  std::deque<std::pair<double, PointCloud>> scans_;
};

}  // namespace

const char* to_string(CloudPoses poses) { return poses == CloudPoses::kOdometry ? "odometry" : "reference"; }

CloudPoses parse_cloud_poses(const std::string& name) {
  if (name == "odometry") return CloudPoses::kOdometry;
  if (name == "reference") return CloudPoses::kReference;
  throw std::invalid_argument("cloud poses must be odometry or reference, not '" + name + "'");
}

std::string odometry_poses_path(const std::string& folder, const std::string& explicit_path) {
  namespace fs = std::filesystem;
  if (!explicit_path.empty()) {
    if (!fs::is_regular_file(explicit_path)) throw IoError(explicit_path + ": odometry poses file not found");
    return explicit_path;
  }
  const fs::path own = fs::path(folder) / "odom_poses.txt";
  if (fs::is_regular_file(own)) return own.string();
  throw IoError(folder +
                ": no odom_poses.txt, and local clouds are built from the vehicle's odometry: give --odometry "
                "FILE (KITTI or TUM poses), or --cloud-poses reference to build them from the reference poses (a "
                "comparison only: no vehicle has those)");
}

void replay_sequence(const Sequence& sequence, const ReplayConfig& config,
                     const std::function<bool(const ReplayQuery&)>& visit,
                     const std::function<void(size_t, size_t)>& progress) {
  config.validate();
  if (config.first >= sequence.size())
    throw std::invalid_argument("replay: first scan " + std::to_string(config.first) + " is past the end of " +
                                sequence.folder() + " (" + std::to_string(sequence.size()) + " scans)");
  const size_t last = std::min(config.last, sequence.size() - 1);
  const size_t total = (last - config.first) / config.stride + 1;
  const Pose3d T_odom_world = sequence.poses()[config.first].inverse();
  // One of the two accumulates, as configured.
  LocalCloud raw(config.local_cloud);
  VoxelAccumulator voxels(config.local_cloud, config.voxel);
  NewestScans newest(config);
  double odometer_m = 0.0, next_query_m = config.single_scan ? 0.0 : std::max(config.warmup_m, 0.0);
  Eigen::Vector3d previous = sequence.poses()[config.first].translation();
  size_t done = 0;
  for (size_t i = config.first; i <= last; i += config.stride) {
    const Pose3d& T_world_sensor = sequence.poses()[i];
    odometer_m += (T_world_sensor.translation() - previous).norm();
    previous = T_world_sensor.translation();
    const Pose3d T_odom_sensor = T_odom_world * T_world_sensor;
    const PointCloud scan = sequence.scan(i).points;
    if (!config.single_scan) {  // a single scan is its own query: nothing accumulates
      if (config.voxelize)
        voxels.add_scan(scan, T_odom_sensor);
      else
        raw.add_scan(scan, T_odom_sensor);
      newest.add(scan, T_odom_sensor, odometer_m);
    }
    if (progress) progress(++done, total);
    if (odometer_m + 1e-9 < next_query_m) continue;
    next_query_m = odometer_m + config.every_m;
    ReplayQuery q;
    q.frame = i;
    q.odometer_m = odometer_m;
    q.T_odom_sensor = T_odom_sensor;
    q.T_world_sensor = T_world_sensor;
    if (config.single_scan) {
      q.cloud_odom = transformed(scan, T_odom_sensor);
      if (config.newest_m > 0.0) q.newest_odom = thinned(q.cloud_odom, config.newest_leaf_m);
    } else {
      q.cloud_odom = config.voxelize ? voxels.crop(T_odom_sensor) : raw.crop(T_odom_sensor);
      q.voxelized = config.voxelize;
      q.newest_odom = newest.points();
    }
    if (!visit(q)) return;
  }
}

}  // namespace io
}  // namespace segmatch
