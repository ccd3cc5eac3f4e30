// The vehicle's side of a query by segments (docs/protocol.md 5.5). A car that knows the
// map's parameters (INFO_REPLY) cuts its local cloud to the map's cylinder, removes the
// ground, segments and describes it with exactly the core functions the server runs for a
// LOCALIZE (segmatch::crop_cylinder, extract_segments[_from_voxels]), and sends the segments:
// a few hundred kilobytes instead of the whole cloud. The server then only retrieves,
// classifies, verifies and refines (Localizer::localize_segments), so both paths give the
// same answer up to the points' quantisation (under 1/32767 of a segment's reach).
#pragma once

#include <segmatch/api/protocol.h>
#include <segmatch/core/localization/localizer.h>
#include <segmatch/io/pipeline_config.h>

#include <cstdint>

namespace segmatch {
namespace vehicle {

class SegmentQuery {
 public:
  // The map's parameters as INFO_REPLY sends them (parameters_json) and their digest. Throws
  // std::runtime_error naming the problem when the JSON does not parse.
  static SegmentQuery from_info(const api::InfoReply& info);
  // parameters_json: the exact bytes the digest is computed over (api::segments_digest).
  explicit SegmentQuery(const std::string& parameters_json);

  // The LOCALIZE request's cloud (raw or voxelized, kFlagVoxelized), sensor pose and prior, as
  // a LOCALIZE_SEGMENTS request with the same id. The segments' points are thinned as the
  // server's refinement would thin them (thin_segment_points, the map's
  // refine.max_segment_points): only what it reads is sent. The refusal-code, detail and newest-scans
  // bits carry over (the newest scans cropped to the map's newest.window_m around the sensor, all
  // the server reads of them). `timings` gets voxel..describe and total (the vehicle's own work,
  // crop included).
  api::LocalizeSegmentsRequest make_request(const api::LocalizeRequest& cloud_request,
                                            ModuleTimings* timings = nullptr) const;

  // The tracking request of a full one (revision 11, docs/protocol.md 5.5): the same segments
  // without their points, the newest scans thinned to the map's track.leaf_m within its
  // track.window_m, bit 5 set. For a vehicle with a fix (a prior and newest scans in `full`);
  // throws std::invalid_argument otherwise. A TRACKING_LOST reply means: send `full`.
  api::LocalizeSegmentsRequest tracking_request(const api::LocalizeSegmentsRequest& full) const;
  // Whether `full` may go as a tracking request: it has the newest scans and a prior whose
  // radius is > 0 and at most the map's max_tracked_radius_m (core/localizer.h; wider ones are
  // not tracked, so the request would only come back TRACKING_LOST).
  bool can_track(const api::LocalizeSegmentsRequest& full) const;

  // What localize_tracking_first did: the reply that counts, the bytes sent in all, and whether
  // a tracking request went first and came back TRACKING_LOST.
  struct TrackedReply {
    api::LocalizeReply reply;
    size_t request_bytes = 0, tracking_bytes = 0;  // all sent; the tracking request's
    bool tracking = false, lost = false;
  };
  // Sends the tracking request of `full` when it can track, and `full` itself when it cannot or
  // the tracking request came back TRACKING_LOST (its server time is added to the reply's).
  // send(request) -> api::LocalizeReply: a Client's localize_segments, or in-process.
  template <typename Send>
  TrackedReply localize_tracking_first(const api::LocalizeSegmentsRequest& full, Send&& send) const {
    TrackedReply out;
    if (can_track(full)) {
      api::LocalizeSegmentsRequest light = tracking_request(full);
      light.flags |= api::kSegmentsFlagRefusalCode;
      out.tracking = true;
      out.request_bytes = out.tracking_bytes = api::encode(light).size();
      out.reply = send(light);
      if (out.reply.refusal != api::RefusalCode::kTrackingLost) return out;
      out.lost = true;
    }
    const float tracking_ms = out.reply.timings.server_total;
    const std::string tracking_reason = out.reply.reason;
    out.request_bytes += api::encode(full).size();
    out.reply = send(full);
    out.reply.timings.server_total += tracking_ms;
    if (out.lost && out.reply.status != api::LocalizeStatus::kLocalized)
      out.reply.reason += " [" + tracking_reason + "]";
    return out;
  }

  // The described segments of a local cloud (query frame), every point kept.
  Segments segment(const PointCloud& cloud, const Eigen::Vector3d& sensor_position, CloudKind kind,
                   ModuleTimings* timings = nullptr) const;

  const io::PipelineConfig& parameters() const { return parameters_; }
  uint64_t digest() const { return digest_; }
  bool sends_esf() const { return send_esf_; }

 private:
  io::PipelineConfig parameters_;
  SegmentationConfig segmentation_;  // the map's, without ESF when its matcher does not read it
  uint64_t digest_ = 0;
  bool send_esf_ = true;
};

}  // namespace vehicle
}  // namespace segmatch
