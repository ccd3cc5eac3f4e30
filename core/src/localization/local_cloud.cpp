// Local cloud accumulation and cylindrical crop (paper III-A, IV-A).
#include "segmatch/core/localization/local_cloud.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "detail/seg_grid.h"

namespace segmatch {

std::vector<uint32_t> detail::subsample_indices(const PointCloud& scan, double leaf_m) {
  std::vector<uint32_t> keep;
  keep.reserve(scan.size());
  if (leaf_m <= 0.0) {
    for (size_t i = 0; i < scan.size(); ++i) {
      if (detail::is_finite(scan[i])) keep.push_back(static_cast<uint32_t>(i));
    }
    return keep;
  }
  const detail::GridFrame frame = detail::GridFrame::fit(scan, leaf_m, false, "LocalCloudConfig.subsample_leaf_m");
  detail::FlatHashMap seen(scan.size() / 4 + 1);
  for (size_t i = 0; i < scan.size(); ++i) {
    if (!detail::is_finite(scan[i])) continue;
    const uint32_t id = static_cast<uint32_t>(keep.size());
    if (seen.insert(frame.key_of(scan[i]), id) == id) keep.push_back(static_cast<uint32_t>(i));
  }
  return keep;
}

void LocalCloudConfig::validate() const {
  if (!(radius_m > 0.0) || !std::isfinite(radius_m)) {
    throw std::invalid_argument("LocalCloudConfig.radius_m must be positive");
  }
  if (!(min_travel_between_scans_m >= 0.0) || !std::isfinite(min_travel_between_scans_m)) {
    throw std::invalid_argument("LocalCloudConfig.min_travel_between_scans_m must be >= 0");
  }
  if (!(subsample_leaf_m >= 0.0) || !std::isfinite(subsample_leaf_m)) {
    throw std::invalid_argument("LocalCloudConfig.subsample_leaf_m must be >= 0");
  }
  if (!(max_scan_age_m >= 0.0) || !std::isfinite(max_scan_age_m)) {
    throw std::invalid_argument("LocalCloudConfig.max_scan_age_m must be >= 0 (0: no limit)");
  }
}

LocalCloud::LocalCloud(const LocalCloudConfig& config) : config_(config) { config_.validate(); }

bool LocalCloud::add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor,
                          const std::vector<uint32_t>* labels) {
  if (labels && labels->size() != scan_sensor.size()) {
    throw std::invalid_argument("LocalCloud::add_scan: labels size differs from scan size");
  }
  const Eigen::Vector3d position = T_world_sensor.translation();
  if (has_last_ && (position - last_position_).norm() < config_.min_travel_between_scans_m) {
    return false;
  }
  if (has_last_) odometer_m_ += (position - last_position_).norm();
  has_last_ = true;
  last_position_ = position;

  Scan scan;
  scan.added_at_m = odometer_m_;
  const std::vector<uint32_t> keep = detail::subsample_indices(scan_sensor, config_.subsample_leaf_m);
  scan.points.reserve(keep.size());
  if (labels) scan.labels.reserve(keep.size());
  const Eigen::Matrix3d R = T_world_sensor.linear();
  detail::reset_xy_bounds(scan.min_xy, scan.max_xy);
  for (uint32_t i : keep) {
    const Point q = detail::world_point(scan_sensor[i], R, position);
    scan.points.push_back(q);
    if (labels) scan.labels.push_back((*labels)[i]);
    detail::grow_xy_bounds(q, scan.min_xy, scan.max_xy);
  }
  scans_.push_back(std::move(scan));
  return true;
}

PointCloud LocalCloud::crop(const Pose3d& T_world_sensor, std::vector<uint32_t>* labels_out) {
  const double cx = T_world_sensor.translation().x();
  const double cy = T_world_sensor.translation().y();
  const double r2 = config_.radius_m * config_.radius_m;
  const auto outside = [&](const Scan& s) {
    return detail::scan_leaves(s.min_xy, s.max_xy, s.points.empty(), s.added_at_m, odometer_m_, cx, cy,
                               config_.radius_m, config_.max_scan_age_m);
  };
  scans_.erase(std::remove_if(scans_.begin(), scans_.end(), outside), scans_.end());

  PointCloud out;
  out.reserve(point_count());
  if (labels_out) {
    labels_out->clear();
    labels_out->reserve(point_count());
  }
  for (const Scan& s : scans_) {
    for (size_t i = 0; i < s.points.size(); ++i) {
      const double dx = s.points[i].x - cx, dy = s.points[i].y - cy;
      if (dx * dx + dy * dy > r2) continue;
      out.push_back(s.points[i]);
      if (labels_out) labels_out->push_back(s.labels.empty() ? 0u : s.labels[i]);
    }
  }
  return out;
}

size_t LocalCloud::point_count() const {
  size_t n = 0;
  for (const Scan& s : scans_) n += s.points.size();
  return n;
}

void LocalCloud::clear() {
  scans_.clear();
  odometer_m_ = 0.0;
  has_last_ = false;
}

}  // namespace segmatch
