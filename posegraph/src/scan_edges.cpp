#include "segmatch/posegraph/scan_edges.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch::posegraph {
namespace {

constexpr double kRadPerDeg = M_PI / 180.0;

void require(bool ok, const std::string& what) {
  if (!ok) throw std::invalid_argument("ScanMatchConfig: " + what);
}

PointCloud thin(const PointCloud& scan, const ScanMatchConfig& c) {
  PointCloud kept;
  kept.reserve(scan.size());
  const float near2 = c.min_range_m * c.min_range_m, far2 = c.max_range_m * c.max_range_m;
  for (const Point& p : scan) {
    const float r2 = p.xyz().squaredNorm();
    if (r2 >= near2 && r2 <= far2) kept.push_back(p);
  }
  VoxelGridConfig grid;
  grid.leaf_m = c.voxel_m;
  grid.min_points_per_voxel = 1;
  return voxel_filter(kept, grid);
}

}  // namespace

void ScanMatchConfig::validate() const {
  require(voxel_m > 0 && std::isfinite(voxel_m), "voxel_m must be > 0");
  require(min_range_m >= 0 && max_range_m > min_range_m && std::isfinite(max_range_m),
          "need 0 <= min_range_m < max_range_m");
  require(target_scans >= 1, "target_scans must be >= 1");
  require(min_fitness >= 0 && min_fitness <= 1, "min_fitness must be in [0, 1]");
  require(max_deviation_m > 0 && max_deviation_fraction >= 0 && max_deviation_deg > 0,
          "the max_deviation bounds must be > 0");
  icp.validate();
}

ScanMatcher::ScanMatcher(const ScanMatchConfig& config) : config_(config) { config_.validate(); }

std::optional<ScanStep> ScanMatcher::add(const PointCloud& scan, const Pose3d& T_odom_sensor) {
  Kept now{thin(scan, config_), Pose3d::Identity()};
  std::optional<ScanStep> step;
  if (!kept_.empty()) {
    const Pose3d T_odom_step = T_odom_last_.inverse() * T_odom_sensor;
    // The target: the kept scans in the newest one's frame.
    PointCloud target;
    for (const Kept& k : kept_)
      for (const Point& p : k.points) {
        Point q = p;
        const Eigen::Vector3f moved = (k.T_last_this * p.xyz().cast<double>()).cast<float>();
        q.x = moved.x(), q.y = moved.y(), q.z = moved.z();
        target.push_back(q);
      }
    const RefineResult icp = refine_alignment(now.points, target, T_odom_step, config_.icp);
    step = ScanStep{};
    step->T_previous_this = icp.T_target_query;
    step->fitness = icp.fitness;
    step->rmse_m = icp.rmse_m;
    const Pose3d deviation = T_odom_step.inverse() * icp.T_target_query;
    const double bound_m = config_.max_deviation_m + config_.max_deviation_fraction * T_odom_step.translation().norm();
    if (icp.fitness < config_.min_fitness)
      step->rejected_because = "low fitness";
    else if (deviation.translation().norm() > bound_m)
      step->rejected_because = "too far from the odometry's step";
    else if (Eigen::AngleAxisd(deviation.linear()).angle() > config_.max_deviation_deg * kRadPerDeg)
      step->rejected_because = "turned too far from the odometry's step";
    else
      step->accepted = true;
    // The kept scans move into the new scan's frame by the step believed.
    const Pose3d T_new_last = (step->accepted ? step->T_previous_this : T_odom_step).inverse();
    for (Kept& k : kept_) k.T_last_this = T_new_last * k.T_last_this;
  }
  kept_.push_front(std::move(now));
  while (static_cast<int>(kept_.size()) > config_.target_scans) kept_.pop_back();
  T_odom_last_ = T_odom_sensor;
  return step;
}

}  // namespace segmatch::posegraph
