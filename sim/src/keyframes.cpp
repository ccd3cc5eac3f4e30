#include "segmatch/sim/keyframes.h"

#include "segmatch/core/detail/random.h"
#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/io/cloud_io.h"
#include "segmatch/io/pose_io.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <stdexcept>

namespace segmatch::sim {
namespace fs = std::filesystem;
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string pcd_name(size_t i) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06zu.pcd", i);
  return buf;
}

// Scans first..last (inclusive) in the keyframe's sensor frame, concatenated. `window` keeps
// the scans of the previous keyframe so that overlapping keyframes read each scan once.
SimulatedScan integrate(const Traversal& t, const ScanSource& scans, size_t first, size_t last,
                        std::map<size_t, SimulatedScan>* window) {
  window->erase(window->begin(), window->lower_bound(first));
  const Pose3d T_kf_world = t.T_world_lidar[last].inverse();
  SimulatedScan out;
  for (size_t j = first; j <= last; ++j) {
    auto it = window->find(j);
    if (it == window->end()) it = window->emplace(j, scans(j)).first;
    const SimulatedScan& s = it->second;
    const Pose3d T_kf_scan = T_kf_world * t.T_world_lidar[j];
    for (const Point& p : s.points) {
      const Eigen::Vector3d q = T_kf_scan * p.xyz().cast<double>();
      out.points.push_back({float(q.x()), float(q.y()), float(q.z()), p.intensity});
    }
    out.labels.insert(out.labels.end(), s.labels.begin(), s.labels.end());
  }
  return out;
}

}  // namespace

void KeyframeConfig::validate() const {
  if (!(every_m >= 0.0 && every_m <= 1000.0)) throw std::invalid_argument("keyframe every_m must be in 0..1000 m");
  if (!(leaf_m >= 0.01f && leaf_m <= 10.0f)) throw std::invalid_argument("keyframe leaf_m must be in 0.01..10 m");
  if (frames < 0 || frames > 100) throw std::invalid_argument("keyframe frames must be in 0..100");
  if (!(std::fabs(odom_scale_error) <= 0.5))
    throw std::invalid_argument("keyframe odom_scale_error must be in -0.5..0.5");
  if (!(std::fabs(odom_yaw_drift_deg_per_m) <= 10.0))
    throw std::invalid_argument("keyframe odom_yaw_drift_deg_per_m must be in -10..10");
  if (!(std::fabs(odom_climb_m_per_m) <= 0.1))
    throw std::invalid_argument("keyframe odom_climb_m_per_m must be in -0.1..0.1");
  if (!(odom_heading_walk_deg_per_sqrt_m >= 0.0 && odom_heading_walk_deg_per_sqrt_m <= 10.0))
    throw std::invalid_argument("keyframe odom_heading_walk_deg_per_sqrt_m must be in 0..10");
  if (!(odom_pitch_walk_deg_per_sqrt_m >= 0.0 && odom_pitch_walk_deg_per_sqrt_m <= 10.0))
    throw std::invalid_argument("keyframe odom_pitch_walk_deg_per_sqrt_m must be in 0..10");
}

int default_keyframe_frames(const LidarModel& model) { return model.pattern == ScanPattern::kRosette ? 5 : 1; }

std::vector<size_t> keyframe_frames(const Traversal& traversal, double every_m, int frames) {
  std::vector<size_t> out;
  const size_t first = static_cast<size_t>(std::max(1, frames)) - 1;
  for (size_t i = first; i < traversal.size(); ++i) {
    if (out.empty() ||
        (traversal.T_world_lidar[i].translation() - traversal.T_world_lidar[out.back()].translation()).norm() >=
            every_m)
      out.push_back(i);
  }
  return out;
}

Poses drifted_odometry(const Poses& T_world_sensor, const KeyframeConfig& c) {
  // No drift: the very same poses (composing the steps again would round differently).
  if (c.odom_scale_error == 0.0 && c.odom_yaw_drift_deg_per_m == 0.0 && c.odom_climb_m_per_m == 0.0 &&
      c.odom_heading_walk_deg_per_sqrt_m == 0.0 && c.odom_pitch_walk_deg_per_sqrt_m == 0.0)
    return T_world_sensor;
  Poses out;
  if (T_world_sensor.empty()) return out;
  Rng walk(c.odom_seed);
  constexpr double kRad = kPi / 180.0;
  double pitch_deg = 0.0;  // the walk's current pitch error: it slants the steps, not the attitude
  out.push_back(T_world_sensor.front());
  for (size_t k = 1; k < T_world_sensor.size(); ++k) {
    const Pose3d step = T_world_sensor[k - 1].inverse() * T_world_sensor[k];
    const double length_m = step.translation().norm();
    const double root = std::sqrt(length_m);
    const double yaw =
        c.odom_yaw_drift_deg_per_m * length_m + c.odom_heading_walk_deg_per_sqrt_m * root * walk.normal();
    pitch_deg += c.odom_pitch_walk_deg_per_sqrt_m * root * walk.normal();
    Pose3d read = step;
    read.translation() *= 1.0 + c.odom_scale_error;
    read.translation().z() += (c.odom_climb_m_per_m + std::tan(pitch_deg * kRad)) * length_m;
    read.linear() = Eigen::AngleAxisd(yaw * kRad, Eigen::Vector3d::UnitZ()).toRotationMatrix() * step.linear();
    out.push_back(out.back() * read);
  }
  return out;
}

KeyframeSummary write_keyframes(const Traversal& traversal, const ScanSource& scans, const KeyframeConfig& c,
                                const std::string& out_dir) {
  c.validate();
  if (c.frames < 1) throw std::invalid_argument("write_keyframes: frames must be resolved (>= 1)");
  const fs::path dir(out_dir);
  fs::create_directories(dir / "scans");
  KeyframeSummary summary;
  summary.frames = keyframe_frames(traversal, c.every_m, c.frames);
  VoxelGridConfig voxels;
  voxels.leaf_m = c.leaf_m;
  voxels.min_points_per_voxel = 1;  // a front end's downsampling keeps lone returns
  std::map<size_t, SimulatedScan> window;
  std::vector<double> times;
  for (size_t k = 0; k < summary.frames.size(); ++k) {
    const size_t f = summary.frames[k];
    const SimulatedScan merged = integrate(traversal, scans, f + 1 - static_cast<size_t>(c.frames), f, &window);
    if (c.write_labels && merged.labels.size() != merged.points.size())
      throw std::runtime_error("write_keyframes: the scans of keyframe " + std::to_string(k) + " have no labels");
    std::vector<uint32_t> labels;
    const PointCloud cloud = voxel_filter(merged.points, voxels, c.write_labels ? &merged.labels : nullptr, &labels);
    io::write_pcd((dir / "scans" / pcd_name(k)).string(), cloud, io::PcdEncoding::kBinary,
                  c.write_labels ? &labels : nullptr);
    summary.points += cloud.size();
    summary.T_world_keyframe.push_back(traversal.T_world_lidar[f]);
    times.push_back(traversal.times_s[f]);
  }
  // World = the first keyframe (exactly the identity), as a SLAM front end starts its map.
  Poses relative;
  for (const Pose3d& T : summary.T_world_keyframe)
    relative.push_back(relative.empty() ? Pose3d::Identity() : summary.T_world_keyframe.front().inverse() * T);
  io::write_kitti_poses((dir / "poses.txt").string(), relative);
  io::write_kitti_poses((dir / "odom_poses.txt").string(), drifted_odometry(relative, c));
  io::write_times((dir / "times.txt").string(), times);
  return summary;
}

}  // namespace segmatch::sim
