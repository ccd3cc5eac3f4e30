#include "query.h"

#include <segmatch/api/tracker.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/replay.h>
#include <segmatch/vehicle/segment_query.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <vector>

namespace segmatch::query {

namespace {
// The detail block (revision 6: the window's warp; 7: method and covariance), in words.
std::string warp_of(const api::LocalizeReply& r) {
  if (!r.detail) return "";
  std::string out;
  char buf[128];
  if (r.detail->window_points > 0) {
    std::snprintf(buf, sizeof buf, "  window warp %.2f m %.2f deg", r.detail->window_warp_m, r.detail->window_warp_deg);
    out += buf;
  }
  if (r.detail->estimate && r.status == api::LocalizeStatus::kLocalized) {
    const Eigen::Matrix<double, 6, 6> c = api::covariance_matrix(r.detail->estimate->covariance_upper);
    std::snprintf(buf, sizeof buf, "  by %s, sigma x %.3f y %.3f m yaw %.2f deg",
                  api::to_string(static_cast<api::ReplyMethod>(r.detail->estimate->method)), std::sqrt(c(3, 3)),
                  std::sqrt(c(4, 4)), std::sqrt(c(2, 2)) * 180.0 / M_PI);
    out += buf;
  }
  return out;
}
}  // namespace

void print_reply(const api::LocalizeReply& r, double round_trip_ms) {
  const Eigen::Quaterniond q(r.T_map_local.linear());
  const Eigen::Vector3d t = r.T_map_local.translation();
  std::printf(
      "%-13s inliers %3u support %3u conf %.2f  T_map_local t=(%.3f %.3f %.3f) q=(%.5f %.5f %.5f %.5f)  "
      "%.1f ms (server %.1f)%s%s%s%s%s\n",
      api::to_string(r.status), r.inliers, r.support, r.confidence, t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z(),
      round_trip_ms, r.timings.server_total, r.refusal == api::RefusalCode::kNone ? "" : "  ",
      r.refusal == api::RefusalCode::kNone ? "" : api::to_string(r.refusal),
      r.reason.empty()                       ? ""
      : r.refusal == api::RefusalCode::kNone ? "  "
                                             : ": ",
      r.reason.c_str(), warp_of(r).c_str());
}

namespace {

// The map's parameters, so the vehicle accumulates and voxelizes as the map was built.
io::PipelineConfig parameters_of(const api::InfoReply& info) {
  try {
    return io::parse_pipeline_config(info.parameters_json, "INFO_REPLY");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "warning: server parameters unreadable (%s); default parameters\n", e.what());
    return io::PipelineConfig{};
  }
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

// The sequence with its scans placed as a vehicle places them: by its odometry (the sequence's
// odom_poses.txt when it has one); says which poses on the first line.
io::Sequence open_as_a_vehicle(const ReplayOptions& options) {
  io::SequenceOptions so;
  so.poses_path = options.odometry;
  so.bag = options.bag;
  const bool bag = io::BagReader::is_bag(options.folder);
  if (!bag && so.poses_path.empty() &&
      std::filesystem::is_regular_file(std::filesystem::path(options.folder) / "odom_poses.txt"))
    so.poses_path = (std::filesystem::path(options.folder) / "odom_poses.txt").string();
  io::Sequence seq = io::Sequence::open(options.folder, so);
  std::printf("local clouds from %s\n", bag                     ? seq.source_note().c_str()
                                        : so.poses_path.empty() ? "the sequence's poses.txt (it has no odom_poses.txt)"
                                                                : so.poses_path.c_str());
  return seq;
}

api::LocalizeRequest request_of(const io::ReplayQuery& q) {
  api::LocalizeRequest request;
  request.request_id = q.frame;
  if (q.voxelized) request.flags |= api::kFlagVoxelized;
  request.flags |= api::kFlagDetail;  // the window's warp, printed per reply
  request.sensor_position_local = q.T_odom_sensor.translation();
  request.sensor_orientation_local = Eigen::Quaterniond(q.T_odom_sensor.linear()).normalized();
  request.points = q.cloud_odom;
  if (!q.newest_odom.empty()) {
    request.flags |= api::kFlagNewestScans;  // revision 8: the answer is the sensor's pose now
    request.newest_points = q.newest_odom;
  }
  return request;
}

}  // namespace

int replay(api::Client& client, const ReplayOptions& options) {
  const io::Sequence seq = open_as_a_vehicle(options);
  io::ReplayConfig config;
  config.every_m = options.every_m;
  config.first = options.first;
  config.last = options.last;
  config.newest_m = options.newest_m;  // LOCALIZE_SEGMENTS carries them too (revision 10)
  const api::InfoReply info = client.info();
  const io::PipelineConfig map_parameters = parameters_of(info);
  // --segments: the vehicle's side (throws, naming the problem, if the parameters do not parse).
  std::unique_ptr<vehicle::SegmentQuery> segmenter;
  if (options.segments) segmenter = std::make_unique<vehicle::SegmentQuery>(vehicle::SegmentQuery::from_info(info));
  std::vector<double> vehicle_ms, request_kb;
  config.local_cloud = map_parameters.local_cloud;
  config.voxel = map_parameters.localizer.segmentation.voxel;
  size_t queries = 0, localized = 0, errors = 0, tracked = 0;
  std::vector<double> latencies_ms;
  api::Tracker tracker;  // --track: the last fix is the next query's prior
  io::replay_sequence(seq, config, [&](const io::ReplayQuery& q) {
    api::LocalizeRequest request = request_of(q);
    ++queries;
    const api::TrackMode mode = options.track ? tracker.prepare(request, q.odometer_m) : api::TrackMode::kGlobal;
    // Tracked with the newest scans: the server tracks on the surface layer first (revision 11).
    if (mode == api::TrackMode::kTracked)
      api::ask_to_track_first(request, max_tracked_radius_m(map_parameters.localizer));
    tracked += mode == api::TrackMode::kTracked;
    std::printf("frame %6zu  %7.1f m  %7zu points  %-7s ", q.frame, q.odometer_m, request.points.size(),
                api::to_string(mode));
    const auto start = std::chrono::steady_clock::now();
    try {
      api::LocalizeReply r;
      if (segmenter) {
        ModuleTimings t;
        const api::LocalizeSegmentsRequest s = segmenter->make_request(request, &t);
        vehicle_ms.push_back(t.total_ms);
        // Tracked, with the newest scans: the tracking request first (revision 11), the full one
        // after TRACKING_LOST.
        const vehicle::SegmentQuery::TrackedReply tr = segmenter->localize_tracking_first(
            s, [&](const api::LocalizeSegmentsRequest& m) { return client.localize_segments(m); });
        request_kb.push_back(static_cast<double>(tr.request_bytes) / 1024.0);
        r = tr.reply;
      } else {
        r = client.localize(request);
      }
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      latencies_ms.push_back(ms);
      localized += r.status == api::LocalizeStatus::kLocalized;
      const bool rejected = options.track && tracker.update(r, q.odometer_m) == api::TrackUpdate::kRejected;
      print_reply(r, ms);
      if (rejected) std::printf("  rejected by the tracker's gate: not a fix (%d so far)\n", tracker.rejections());
    } catch (const api::ClientError& e) {
      ++errors;
      std::printf("error: %s\n", e.what());
      if (client.broken()) return false;
    }
    return true;
  });
  std::printf("summary: %zu queries (%zu tracked), %zu localized, %zu errors, latency p50 %.1f ms p99 %.1f ms\n",
              queries, tracked, localized, errors, percentile(latencies_ms, 0.5), percentile(latencies_ms, 0.99));
  if (segmenter)
    std::printf("segments: vehicle side p50 %.1f ms per query (segmenting, describing), request p50 %.0f KB\n",
                percentile(vehicle_ms, 0.5), percentile(request_kb, 0.5));
  return errors == 0 ? 0 : 1;
}

}  // namespace segmatch::query
