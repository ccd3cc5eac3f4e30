#include "segmatch/core/mapping/map_builder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <unordered_map>

namespace segmatch {
namespace {

// The map builder's map never holds two segments within the duplicate distance.
SegmentMapConfig resolving(SegmentMapConfig c) {
  c.resolve_moved_duplicates = true;
  return c;
}

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

void MapBuilderConfig::validate() const {
  local_cloud.validate();
  segmentation.validate();
  segment_map.validate();
  surfaces.validate();
  if (!(map_every_m > 0.0) || !std::isfinite(map_every_m))
    throw std::invalid_argument("MapBuilderConfig.map_every_m must be positive");
}

MapBuilder::MapBuilder(const MapBuilderConfig& config)
    : config_((config.validate(), config)),
      local_(without_age_limit(config.local_cloud), config.segmentation.voxel),
      map_(resolving(config.segment_map)),
      surfaces_(config.surfaces) {}

bool MapBuilder::add_scan(const PointCloud& points_sensor, const Pose3d& T_world_sensor, uint32_t scan_index,
                          const std::vector<uint32_t>* labels) {
  if (has_scan_) odometer_m_ += (T_world_sensor.translation() - T_world_last_.translation()).norm();
  has_scan_ = true;
  T_world_last_ = T_world_sensor;
  last_index_ = scan_index;
  has_labels_ = has_labels_ || labels != nullptr;
  const auto start = std::chrono::steady_clock::now();
  local_.add_scan(points_sensor, T_world_sensor, labels);
  surfaces_.add_scan(points_sensor, T_world_sensor);
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
  const PointCloud voxels = local_.crop(T_world_last_, has_labels_ ? &labels : nullptr);
  timings_.crop_ms += ms_since(start);

  ModuleTimings t;
  Segments segments = extract_segments_from_voxels(voxels, T_world_last_.translation().cast<float>(),
                                                   config_.segmentation, has_labels_ ? &labels : nullptr, &t);
  timings_.voxel_ms += t.voxel_ms;
  timings_.ground_ms += t.ground_ms;
  timings_.segment_ms += t.segment_ms;
  timings_.describe_ms += t.describe_ms;
  extracted_segments_ += segments.size();

  start = std::chrono::steady_clock::now();
  map_.add(std::move(segments));
  // SegmentMap replaces a segment only by a view with more points (keeping its id), appends
  // new ones and drops views it resolved as duplicates, so a new id or a changed point count
  // is exactly a view from this local cloud.
  const Segments& all = map_.segments();
  std::unordered_map<uint64_t, View> views;
  views.reserve(all.size());
  keyframe_of_segment_.resize(all.size());
  for (size_t i = 0; i < all.size(); ++i) {
    const auto it = view_of_id_.find(all[i].id);
    View v{last_index_, all[i].points.size()};
    if (it != view_of_id_.end() && it->second.points == v.points) v = it->second;
    views.emplace(all[i].id, v);
    keyframe_of_segment_[i] = v.keyframe;
  }
  view_of_id_ = std::move(views);
  timings_.merge_ms += ms_since(start);
}

const std::vector<uint32_t>& MapBuilder::keyframe_of_segment() const { return keyframe_of_segment_; }

}  // namespace segmatch
