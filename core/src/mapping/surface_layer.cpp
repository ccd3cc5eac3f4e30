#include "segmatch/core/mapping/surface_layer.h"

#include "segmatch/core/preprocess/preprocess.h"

#include "detail/config_checks.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch {

namespace {

VoxelGridConfig grid_of(const SurfaceLayerConfig& c) {
  VoxelGridConfig g;
  g.leaf_m = c.leaf_m;
  g.min_points_per_voxel = 1;
  return g;
}

}  // namespace

void SurfaceLayerConfig::validate() const {
  auto positive = [](float v, const char* name) { detail::require_positive(v, "SurfaceLayerConfig", name); };
  positive(leaf_m, "leaf_m");
  positive(max_range_m, "max_range_m");
  positive(tile_m, "tile_m");
  if (tile_m < leaf_m) throw std::invalid_argument("SurfaceLayerConfig.tile_m must be >= leaf_m");
}

SurfaceAccumulator::SurfaceAccumulator(const SurfaceLayerConfig& config) : config_((config.validate(), config)) {}

void SurfaceAccumulator::add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor) {
  ++scans_;
  if (!config_.enabled) return;
  const float r2 = config_.max_range_m * config_.max_range_m;
  PointCloud near;
  near.reserve(scan_sensor.size());
  for (const Point& p : scan_sensor)
    if (p.x * p.x + p.y * p.y <= r2) near.push_back(p);
  for (Point p : voxel_filter(near, grid_of(config_))) {
    const Eigen::Vector3d q = T_world_sensor * Eigen::Vector3d(p.x, p.y, p.z);
    p.x = static_cast<float>(q.x()), p.y = static_cast<float>(q.y()), p.z = static_cast<float>(q.z());
    p.intensity = 0.0f;
    points_.push_back(p);
  }
  if (points_.size() > 2 * thinned_size_ + 1'000'000) {
    points_ = voxel_filter(points_, grid_of(config_));
    thinned_size_ = points_.size();
  }
}

PointCloud SurfaceAccumulator::points() const { return voxel_filter(points_, grid_of(config_)); }

}  // namespace segmatch
