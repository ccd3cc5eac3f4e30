#include "segmatch/vehicle/segment_query.h"

#include <segmatch/api/tracker.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace segmatch {
namespace vehicle {

SegmentQuery SegmentQuery::from_info(const api::InfoReply& info) { return SegmentQuery(info.parameters_json); }

SegmentQuery::SegmentQuery(const std::string& parameters_json)
    : parameters_(io::parse_pipeline_config(parameters_json, "the map's parameters (INFO_REPLY)")),
      segmentation_(parameters_.localizer.segmentation),
      digest_(api::segments_digest(parameters_json)),
      send_esf_(parameters_.localizer.matcher.needs_esf()) {
  // ESF is the expensive descriptor; a map matched on eigen features alone does not read it.
  segmentation_.descriptors.compute_esf = segmentation_.descriptors.compute_esf && send_esf_;
  if (send_esf_ && !segmentation_.descriptors.compute_esf)
    throw std::runtime_error("the map's matcher compares ESF histograms but its parameters do not compute them");
  segmentation_.validate();
}

Segments SegmentQuery::segment(const PointCloud& cloud, const Eigen::Vector3d& sensor_position, CloudKind kind,
                               ModuleTimings* timings) const {
  const auto start = std::chrono::steady_clock::now();
  ModuleTimings local;
  ModuleTimings& t = timings ? *timings : local;
  // As the server does for a LOCALIZE (server/src/map_service.cpp, Localizer::localize).
  const PointCloud cropped = crop_cylinder(cloud, sensor_position, parameters_.local_cloud.radius_m);
  const Eigen::Vector3f sensor = sensor_position.cast<float>();
  Segments segments = kind == CloudKind::kVoxelized
                          ? extract_segments_from_voxels(cropped, sensor, segmentation_, nullptr, &t)
                          : extract_segments(cropped, sensor, segmentation_, nullptr, &t);
  t.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return segments;
}

api::LocalizeSegmentsRequest SegmentQuery::make_request(const api::LocalizeRequest& c, ModuleTimings* timings) const {
  api::LocalizeSegmentsRequest r;
  r.request_id = c.request_id;
  if (c.flags & api::kFlagHasPrior) r.flags |= api::kSegmentsFlagHasPrior;
  if (send_esf_) r.flags |= api::kSegmentsFlagEsf;
  if (c.flags & api::kFlagRefusalCode) r.flags |= api::kSegmentsFlagRefusalCode;
  if (c.flags & api::kFlagDetail) r.flags |= api::kSegmentsFlagDetail;
  if (c.flags & api::kFlagNewestScans) {  // revision 10: the sensor's pose now on this path too
    r.flags |= api::kSegmentsFlagNewestScans;
    // Only the points the server reads (its newest.window_m around the sensor) travel.
    r.newest_points = crop_cylinder(c.newest_points, c.sensor_position_local, parameters_.localizer.newest.window_m);
  }
  r.sensor_position_local = c.sensor_position_local;
  r.sensor_orientation_local = c.sensor_orientation_local;
  r.T_map_local_prior = c.T_map_local_prior;
  r.prior_radius_m = c.prior_radius_m;
  // LOCALIZE without its heading bit means the server's default (PosePrior: 10 deg).
  r.prior_heading_tolerance_deg = (c.flags & api::kFlagPriorHeading) ? c.prior_heading_tolerance_deg : 10.0;
  r.parameters_digest = digest_;
  const CloudKind kind = (c.flags & api::kFlagVoxelized) ? CloudKind::kVoxelized : CloudKind::kRaw;
  const auto start = std::chrono::steady_clock::now();
  r.segments = segment(c.points, c.sensor_position_local, kind, timings);
  thin_segment_points(r.segments, static_cast<size_t>(parameters_.localizer.refine.max_segment_points));
  if (timings)
    timings->total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return r;
}

bool SegmentQuery::can_track(const api::LocalizeSegmentsRequest& full) const {
  return api::can_track(full.flags & api::kSegmentsFlagHasPrior, full.flags & api::kSegmentsFlagNewestScans,
                        full.prior_radius_m, max_tracked_radius_m(parameters_.localizer));
}

api::LocalizeSegmentsRequest SegmentQuery::tracking_request(const api::LocalizeSegmentsRequest& full) const {
  const uint32_t needs = api::kSegmentsFlagHasPrior | api::kSegmentsFlagNewestScans;
  if ((full.flags & needs) != needs)
    throw std::invalid_argument(
        "a tracking request needs a prior and the newest scans (LOCALIZE_SEGMENTS bits 0 and 4)");
  const SurfaceTrackingConfig& track = parameters_.localizer.track;
  api::LocalizeSegmentsRequest r = full;
  r.flags |= api::kSegmentsFlagTrack;
  r.segments.clear();
  for (const Segment& s : full.segments) {  // the support check reads centroids and features only
    if ((s.centroid.cast<double>() - full.sensor_position_local).head<2>().norm() > track.window_m) continue;
    r.segments.push_back(s);
    r.segments.back().points.clear();
  }
  VoxelGridConfig thin;
  thin.leaf_m = track.leaf_m;
  thin.min_points_per_voxel = 1;
  const PointCloud newest =
      voxel_filter(crop_cylinder(full.newest_points, full.sensor_position_local, track.window_m), thin);
  const size_t step = (newest.size() + track.max_points - 1) / static_cast<size_t>(track.max_points);
  r.newest_points.clear();
  for (size_t i = 0; i < newest.size(); i += std::max<size_t>(step, 1)) r.newest_points.push_back(newest[i]);
  return r;
}

}  // namespace vehicle
}  // namespace segmatch
