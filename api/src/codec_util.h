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
// The first failure wins.
DecodeStatus first_error(std::initializer_list<DecodeStatus> statuses);

}  // namespace detail
}  // namespace api
}  // namespace segmatch
