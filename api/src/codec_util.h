// Shared by the codec's translation units.
#pragma once

#include "segmatch/api/protocol.h"
#include "wire.h"

#include <initializer_list>

namespace segmatch {
namespace api {
namespace detail {

// Header + payload as one frame.
std::vector<uint8_t> frame(MessageType type, wire::Writer& payload);
// kOk when the reader consumed exactly its bytes.
DecodeStatus finish(const wire::Reader& r);

// Poses and vectors of the requests (localize_codec.cpp). The getters return kNonFinite /
// kBadQuaternion on bad values and kOk on a short read (finish() reports it as truncated).
void put_quaternion(wire::Writer& w, const Eigen::Quaterniond& q);
void put_pose(wire::Writer& w, const Pose3d& T);
DecodeStatus get_quaternion(wire::Reader& r, Eigen::Quaterniond& q);
DecodeStatus get_vector(wire::Reader& r, Eigen::Vector3d& v);
DecodeStatus get_pose(wire::Reader& r, Pose3d& T);
// `count` points of `stride` floats (3: x y z, intensity 0; 4: x y z intensity); kNonFinite if
// any value is not finite.
DecodeStatus get_points(wire::Reader& r, uint32_t count, uint32_t stride, PointCloud& points);
// The vehicle's newest scans (LOCALIZE bit 5, LOCALIZE_SEGMENTS bit 4): count, then x y z f32.
void put_newest_points(wire::Writer& w, const PointCloud& points);
// The first failure wins.
DecodeStatus first_error(std::initializer_list<DecodeStatus> statuses);

// The first 132 bytes of LOCALIZE and LOCALIZE_SEGMENTS (docs/protocol.md 5.4, 5.5): request
// id, flags, the sensor's position and orientation in the local frame, the prior's pose and
// radius (both request structs name these fields alike).
template <typename Request>
void put_request_head(wire::Writer& w, const Request& m) {
  w.u64(m.request_id);
  w.u32(m.flags);
  for (int i = 0; i < 3; ++i) w.f64(m.sensor_position_local[i]);
  put_quaternion(w, m.sensor_orientation_local);
  put_pose(w, m.T_map_local_prior);
  w.f64(m.prior_radius_m);
}

// Reads them; returns the first bad pose value (kNonFinite, kBadQuaternion) or kOk, for the
// caller to report after its own flag and length checks.
template <typename Request>
DecodeStatus get_request_head(wire::Reader& r, Request& m) {
  m.request_id = r.u64();
  m.flags = r.u32();
  const DecodeStatus s_pos = get_vector(r, m.sensor_position_local);
  const DecodeStatus s_q = get_quaternion(r, m.sensor_orientation_local);
  const DecodeStatus s_prior = get_pose(r, m.T_map_local_prior);
  m.prior_radius_m = r.f64();
  return first_error({s_pos, s_q, s_prior});
}

}  // namespace detail
}  // namespace api
}  // namespace segmatch
