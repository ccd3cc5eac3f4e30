#include "segmatch/core/map_builder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <unordered_map>

namespace segmatch {
namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Cell of a cubic grid of edge d, packed into 64 bits (21 bits per axis).
uint64_t cell_key(const Eigen::Vector3f& p, float d, int dx = 0, int dy = 0, int dz = 0) {
  auto axis = [d](float v, int offset) {
    return static_cast<uint64_t>(static_cast<int64_t>(std::floor(v / d)) + offset + (1 << 20)) & 0x1FFFFF;
  };
  return axis(p.x(), dx) | (axis(p.y(), dy) << 21) | (axis(p.z(), dz) << 42);
}

}  // namespace

void MapBuilderConfig::validate() const {
  local_cloud.validate();
  segmentation.validate();
  segment_map.validate();
  if (!(map_every_m > 0.0) || !std::isfinite(map_every_m))
    throw std::invalid_argument("MapBuilderConfig.map_every_m must be positive");
}

MapBuilder::MapBuilder(const MapBuilderConfig& config)
    : config_(config), local_(config.local_cloud), map_(config.segment_map) {
  config_.validate();
}

bool MapBuilder::add_scan(const PointCloud& points_sensor, const Pose3d& T_world_sensor, uint32_t scan_index,
                          const std::vector<uint32_t>* labels) {
  if (has_scan_) odometer_m_ += (T_world_sensor.translation() - T_world_last_.translation()).norm();
  has_scan_ = true;
  T_world_last_ = T_world_sensor;
  last_index_ = scan_index;
  has_labels_ = has_labels_ || labels != nullptr;
  const auto start = std::chrono::steady_clock::now();
  local_.add_scan(points_sensor, T_world_sensor, labels);
  timings_.accumulate_ms += ms_since(start);
  if (odometer_m_ - segmented_at_m_ < config_.map_every_m) return false;
  segment_local_cloud();
  return true;
}

bool MapBuilder::finish() {
  // Nothing new since the last segmented cloud: the same crop would add nothing.
  if (!has_scan_ || (local_clouds_ > 0 && odometer_m_ == segmented_at_m_)) return false;
  segment_local_cloud();
  return true;
}

void MapBuilder::segment_local_cloud() {
  segmented_at_m_ = odometer_m_;
  ++local_clouds_;
  auto start = std::chrono::steady_clock::now();
  std::vector<uint32_t> labels;
  const PointCloud cloud = local_.crop(T_world_last_, &labels);
  timings_.crop_ms += ms_since(start);

  ModuleTimings t;
  Segments segments = extract_segments(cloud, T_world_last_.translation().cast<float>(), config_.segmentation,
                                       has_labels_ ? &labels : nullptr, &t);
  timings_.voxel_ms += t.voxel_ms;
  timings_.ground_ms += t.ground_ms;
  timings_.segment_ms += t.segment_ms;
  timings_.describe_ms += t.describe_ms;
  extracted_segments_ += segments.size();

  start = std::chrono::steady_clock::now();
  map_.add(std::move(segments));
  consolidated_ = false;
  // SegmentMap replaces a segment only by a view with more points and appends new ones, so a
  // changed point count or a new index is exactly a view from this local cloud.
  const Segments& all = map_.segments();
  for (size_t i = 0; i < all.size(); ++i) {
    if (i == keyframe_of_segment_.size()) {
      keyframe_of_segment_.push_back(last_index_);
      points_of_segment_.push_back(all[i].points.size());
    } else if (all[i].points.size() != points_of_segment_[i]) {
      keyframe_of_segment_[i] = last_index_;
      points_of_segment_[i] = all[i].points.size();
    }
  }
  timings_.merge_ms += ms_since(start);
}


const Segments& MapBuilder::segments() const {
  if (!consolidated_) consolidate();
  return segments_;
}

const std::vector<uint32_t>& MapBuilder::keyframe_of_segment() const {
  if (!consolidated_) consolidate();
  return keyframes_;
}

// Greedy, most points first: a segment is kept unless a kept one lies within the duplicate
// distance. Output keeps the map's order (ids ascending), so ids stay stable across calls.
void MapBuilder::consolidate() const {
  const Segments& all = map_.segments();
  const float d = config_.segment_map.duplicate_distance_m;
  std::vector<size_t> order(all.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return all[a].points.size() > all[b].points.size(); });
  std::unordered_multimap<uint64_t, size_t> kept_cells;
  std::vector<bool> keep(all.size(), false);
  for (size_t i : order) {
    bool duplicate = false;
    for (int dx = -1; dx <= 1 && !duplicate; ++dx)
      for (int dy = -1; dy <= 1 && !duplicate; ++dy)
        for (int dz = -1; dz <= 1 && !duplicate; ++dz) {
          const auto range = kept_cells.equal_range(cell_key(all[i].centroid, d, dx, dy, dz));
          for (auto it = range.first; it != range.second && !duplicate; ++it)
            duplicate = (all[it->second].centroid - all[i].centroid).norm() < d;
        }
    if (duplicate) continue;
    keep[i] = true;
    kept_cells.emplace(cell_key(all[i].centroid, d), i);
  }
  segments_.clear();
  keyframes_.clear();
  for (size_t i = 0; i < all.size(); ++i)
    if (keep[i]) segments_.push_back(all[i]), keyframes_.push_back(keyframe_of_segment_[i]);
  consolidated_ = true;
}

}  // namespace segmatch
