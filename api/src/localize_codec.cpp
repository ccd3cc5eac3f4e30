// LOCALIZE and LOCALIZE_REPLY payloads (docs/protocol.md, sections 5.4 and 6.4).
#include "segmatch/api/protocol.h"

#include "codec_util.h"

#include <cmath>

namespace segmatch {
namespace api {
namespace detail {

void put_quaternion(wire::Writer& w, const Eigen::Quaterniond& q_in) {
  const Eigen::Quaterniond q = q_in.normalized();
  w.f64(q.w()), w.f64(q.x()), w.f64(q.y()), w.f64(q.z());
}

void put_pose(wire::Writer& w, const Pose3d& T) {
  put_quaternion(w, Eigen::Quaterniond(T.linear()));
  for (int i = 0; i < 3; ++i) w.f64(T.translation()[i]);
}

// Reads w x y z; kNonFinite / kBadQuaternion on bad values (checked once the read succeeded).
DecodeStatus get_quaternion(wire::Reader& r, Eigen::Quaterniond& q) {
  const double w = r.f64(), x = r.f64(), y = r.f64(), z = r.f64();
  if (r.failed()) return DecodeStatus::kOk;  // reported as truncated by finish()
  if (!(std::isfinite(w) && std::isfinite(x) && std::isfinite(y) && std::isfinite(z))) return DecodeStatus::kNonFinite;
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) return DecodeStatus::kBadQuaternion;
  q = Eigen::Quaterniond(w / norm, x / norm, y / norm, z / norm);
  return DecodeStatus::kOk;
}

DecodeStatus get_vector(wire::Reader& r, Eigen::Vector3d& v) {
  for (int i = 0; i < 3; ++i) v[i] = r.f64();
  if (!r.failed() && !v.allFinite()) return DecodeStatus::kNonFinite;
  return DecodeStatus::kOk;
}

DecodeStatus get_pose(wire::Reader& r, Pose3d& T) {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  DecodeStatus s = get_quaternion(r, q);
  const DecodeStatus st = get_vector(r, t);
  if (s == DecodeStatus::kOk) s = st;
  T = Pose3d::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = t;
  return s;
}

// The first failure wins; a read past the end is reported as truncated.
DecodeStatus first_error(std::initializer_list<DecodeStatus> statuses) {
  for (DecodeStatus s : statuses)
    if (s != DecodeStatus::kOk) return s;
  return DecodeStatus::kOk;
}

}  // namespace detail

namespace {

using namespace detail;

// Fixed part of a LOCALIZE payload before the points.
constexpr size_t kLocalizeFixedBytes = 8 + 4 + 3 * 8 + 4 * 8 + 4 * 8 + 3 * 8 + 8 + 4 + 4;
static_assert(kLocalizeFixedBytes == 140, "docs/protocol.md documents 140 bytes");

// Points are 4 packed floats, the wire layout of stride 4: read in one go.
static_assert(sizeof(Point) == 4 * sizeof(float), "Point must stay x y z intensity");

}  // namespace

void detail::put_newest_points(wire::Writer& w, const PointCloud& points) {
  w.u32(static_cast<uint32_t>(points.size()));
  for (const Point& p : points) w.f32s(&p.x, 3);
}

DecodeStatus detail::get_points(wire::Reader& r, uint32_t count, uint32_t stride, PointCloud& points) {
  points.resize(count);
  if (stride == 4) {
    if (count > 0 && !r.f32s(&points[0].x, 4 * static_cast<size_t>(count))) return DecodeStatus::kTruncated;
  } else {
    for (Point& p : points)
      if (!r.f32s(&p.x, 3)) return DecodeStatus::kTruncated;
  }
  for (const Point& p : points)
    if (!(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && std::isfinite(p.intensity)))
      return DecodeStatus::kNonFinite;
  return DecodeStatus::kOk;
}

namespace {

std::array<float*, kTimingCount> timing_fields(ModuleTimingsMs& t) {
  return {&t.voxel,    &t.ground, &t.segment, &t.describe, &t.retrieve,
          &t.classify, &t.verify, &t.refine,  &t.total,    &t.server_total};
}

}  // namespace

std::vector<uint8_t> encode(const LocalizeRequest& m) {
  wire::Writer w;
  const uint32_t stride = m.point_stride == 3 ? 3 : 4;
  w.reserve(kLocalizeFixedBytes + m.points.size() * stride * 4);
  put_request_head(w, m);
  w.u32(static_cast<uint32_t>(m.points.size()));
  w.u32(stride);
  if (stride == 4 && !m.points.empty()) {
    w.f32s(&m.points[0].x, 4 * m.points.size());
  } else {
    for (const Point& p : m.points) w.f32s(&p.x, 3);
  }
  if (m.flags & kFlagPriorHeading) w.f64(m.prior_heading_tolerance_deg);
  if (m.flags & kFlagNewestScans) put_newest_points(w, m.newest_points);  // revision 8
  return detail::frame(type_of(m), w);
}

DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, LocalizeRequest& out) {
  if (size < kLocalizeFixedBytes) return DecodeStatus::kTruncated;
  wire::Reader r(payload, size);
  LocalizeRequest m;
  const DecodeStatus s_head = get_request_head(r, m);
  const uint32_t count = r.u32();
  m.point_stride = r.u32();
  if (m.flags & ~kKnownFlags) return DecodeStatus::kBadField;
  // Tracking first (revision 11) registers the newest scans around the prior: both must be there.
  if ((m.flags & kFlagTrack) && (m.flags & (kFlagHasPrior | kFlagNewestScans)) != (kFlagHasPrior | kFlagNewestScans))
    return DecodeStatus::kBadField;
  if (m.point_stride != 3 && m.point_stride != 4) return DecodeStatus::kBadStride;
  // 64-bit arithmetic: count * stride * 4 cannot overflow.
  const uint64_t trailer = (m.flags & kFlagPriorHeading) ? 8 : 0;
  const uint64_t points_end = kLocalizeFixedBytes + static_cast<uint64_t>(count) * m.point_stride * 4 + trailer;
  // With the newest scans (revision 8) their count follows; it is checked once read.
  if ((m.flags & kFlagNewestScans) ? points_end + 4 > size : points_end != size) return DecodeStatus::kBadPointCount;
  DecodeStatus s = s_head;
  if (s != DecodeStatus::kOk) return s;
  if (!std::isfinite(m.prior_radius_m)) return DecodeStatus::kNonFinite;
  if (m.prior_radius_m < 0.0) return DecodeStatus::kBadField;
  s = get_points(r, count, m.point_stride, m.points);
  if (s != DecodeStatus::kOk) return s;
  if (m.flags & kFlagPriorHeading) {
    m.prior_heading_tolerance_deg = r.f64();
    if (!std::isfinite(m.prior_heading_tolerance_deg)) return DecodeStatus::kNonFinite;
    if (m.prior_heading_tolerance_deg < 0.0) return DecodeStatus::kBadField;
  }
  if (m.flags & kFlagNewestScans) {
    const uint64_t newest = r.u32();
    if (newest * 12 != r.remaining()) return DecodeStatus::kBadPointCount;
    s = get_points(r, static_cast<uint32_t>(newest), 3, m.newest_points);
    if (s != DecodeStatus::kOk) return s;
  }
  s = detail::finish(r);
  if (s == DecodeStatus::kOk) out = std::move(m);
  return s;
}

// The detail block (revision 6): its length, the fields this revision knows, the rest skipped.
DecodeStatus get_reply_detail(wire::Reader& r, LocalizeReply& m) {
  const uint16_t bytes = r.u16();
  if (r.failed()) return DecodeStatus::kTruncated;
  if (bytes != r.remaining()) return bytes > r.remaining() ? DecodeStatus::kTruncated : DecodeStatus::kTrailingBytes;
  if (bytes < kReplyDetailBytes) return DecodeStatus::kBadField;
  ReplyDetail d;
  d.window_warp_m = r.f32();
  d.window_warp_deg = r.f32();
  d.window_points = r.u32();
  size_t known = kReplyDetailBytes;
  if (bytes >= kReplyDetailEstimateBytes) {  // revision 7
    ReplyDetail::Estimate e;
    e.method = r.u8();
    for (int k = 0; k < 3; ++k) (void)r.u8();  // reserved
    for (float& c : e.covariance_upper) {
      c = r.f32();
      if (!std::isfinite(c)) return DecodeStatus::kNonFinite;
    }
    d.estimate = e;
    known = kReplyDetailEstimateBytes;
  }
  for (size_t k = known; k < bytes; ++k) (void)r.u8();  // a later revision's fields
  if (!std::isfinite(d.window_warp_m) || !std::isfinite(d.window_warp_deg)) return DecodeStatus::kNonFinite;
  m.detail = d;
  return DecodeStatus::kOk;
}

std::vector<uint8_t> encode(const LocalizeReply& m) {
  wire::Writer w;
  w.u64(m.request_id);
  w.u16(static_cast<uint16_t>(m.status));
  w.u16(static_cast<uint16_t>(m.refusal));
  w.str(m.reason);
  put_pose(w, m.T_map_local);
  w.u32(m.inliers);
  w.f32(m.confidence);
  w.u32(m.support);
  w.u32(static_cast<uint32_t>(m.matched_segment_ids.size()));
  for (uint64_t id : m.matched_segment_ids) w.u64(id);
  ModuleTimingsMs t = m.timings;
  for (float* f : timing_fields(t)) w.f32(*f);
  if (m.detail) {  // revision 6: a block with its own length (docs/protocol.md 6.4)
    const auto& e = m.detail->estimate;
    w.u16(static_cast<uint16_t>(e ? kReplyDetailEstimateBytes : kReplyDetailBytes));
    w.f32(m.detail->window_warp_m);
    w.f32(m.detail->window_warp_deg);
    w.u32(m.detail->window_points);
    if (e) {  // revision 7
      w.u8(e->method);
      for (int k = 0; k < 3; ++k) w.u8(0);
      for (float c : e->covariance_upper) w.f32(c);
    }
  }
  return detail::frame(type_of(m), w);
}

DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, LocalizeReply& out) {
  wire::Reader r(payload, size);
  LocalizeReply m;
  m.request_id = r.u64();
  const uint16_t status = r.u16();
  m.refusal = static_cast<RefusalCode>(r.u16());  // any value: a later revision's code too
  m.reason = r.str(limits.max_string_bytes);
  const DecodeStatus s_pose = get_pose(r, m.T_map_local);
  m.inliers = r.u32();
  m.confidence = r.f32();
  m.support = r.u32();
  const uint32_t ids = r.u32();
  if (r.failed()) return r.too_long() ? DecodeStatus::kBadField : DecodeStatus::kTruncated;
  if (static_cast<uint64_t>(ids) * 8 + kTimingCount * 4 > r.remaining()) return DecodeStatus::kTruncated;
  m.matched_segment_ids.resize(ids);
  for (uint64_t& id : m.matched_segment_ids) id = r.u64();
  for (float* f : timing_fields(m.timings)) *f = r.f32();
  const DecodeStatus s_detail = r.remaining() > 0 ? get_reply_detail(r, m) : DecodeStatus::kOk;
  DecodeStatus s = first_error({s_pose, s_detail, detail::finish(r)});
  if (s == DecodeStatus::kOk && status > 2) s = DecodeStatus::kBadField;
  if (s == DecodeStatus::kOk && !std::isfinite(m.confidence)) s = DecodeStatus::kNonFinite;
  if (s != DecodeStatus::kOk) return s;
  m.status = static_cast<LocalizeStatus>(status);
  out = std::move(m);
  return s;
}

}  // namespace api
}  // namespace segmatch
