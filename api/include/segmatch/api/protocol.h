// The localization protocol (docs/protocol.md, byte by byte): framed little-endian messages
// over TCP. Every frame is a 12-byte header (magic "SGMQ", version u16, type u16, payload
// length u32) followed by the payload.
//
// Encoding never fails on a valid struct. Decoding never throws and never reads outside the
// given bytes: it returns a DecodeStatus saying what is wrong with them, and only kOk means
// the output was filled.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/core/segmentation/segment.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace segmatch {
namespace api {

constexpr std::array<uint8_t, 4> kMagic = {'S', 'G', 'M', 'Q'};
constexpr uint16_t kProtocolVersion = 1;
// The protocol document's revision (docs/protocol.md, History): messages, flag bits and error
// codes added compatibly since version 1. The frame header still says kProtocolVersion.
constexpr int kProtocolRevision = 12;
constexpr size_t kHeaderBytes = 12;

enum class MessageType : uint16_t {
  kHello = 0x0001,  // request: shared-secret token (first message when the server has one)
  kPing = 0x0002,
  kInfo = 0x0003,
  kLocalize = 0x0004,
  kLocalizeSegments = 0x0005,  // revision 3: the vehicle's segments instead of its cloud
  kHelloOk = 0x8001,           // replies have the high bit set
  kPong = 0x8002,
  kInfoReply = 0x8003,
  kLocalizeReply = 0x8004,
  kError = 0x80FF,
};
bool is_known_type(uint16_t type);
const char* to_string(MessageType type);

enum class DecodeStatus {
  kOk,
  kIncomplete,  // header: fewer than kHeaderBytes; frame: payload not all there yet
  kBadMagic,
  kBadVersion,
  kUnknownType,
  kTooLarge,       // payload length over the configured limit
  kTruncated,      // payload shorter than its fields need
  kTrailingBytes,  // payload longer than its fields
  kBadPointCount,  // point count * stride disagrees with the payload length
  kBadStride,      // point stride other than 3 or 4
  kNonFinite,      // NaN or Inf in a coordinate, pose or radius
  kBadQuaternion,  // norm not within kQuaternionNormTolerance of 1
  kBadField,       // reserved flag bits set, string too long, negative radius, ...
};
const char* to_string(DecodeStatus status);

// Error codes of ERROR replies (u16 on the wire).
enum class ErrorCode : uint16_t {
  kBadMagic = 1,
  kUnsupportedVersion = 2,
  kUnknownType = 3,
  kMalformed = 4,  // truncated payload, trailing bytes, bad field
  kFrameTooLarge = 5,
  kBadPointCount = 6,
  kNonFinite = 7,
  kBadQuaternion = 8,
  kAuthRequired = 9,        // the server has a token and the first message was not HELLO
  kAuthFailed = 10,         // wrong token
  kServerBusy = 11,         // max connections reached
  kInternal = 12,           // the localizer threw; the connection stays usable
  kUnexpectedMessage = 13,  // a reply type sent as a request, or a second HELLO
  kShuttingDown = 14,
  // Revision 3: LOCALIZE_SEGMENTS computed with other parameters than the map's (digest), or
  // without a descriptor the map's matcher needs. The connection stays usable.
  kParametersMismatch = 15,
  // The request ran past the server's --request-timeout-s (counted from its arrival, queueing
  // included); its worker stopped and took the next request. The connection stays usable.
  kRequestTimeout = 16,
};
ErrorCode error_code_for(DecodeStatus status);
// Whether the byte stream is still in sync after this decode failure (the whole frame could
// be skipped): header errors lose the framing, payload errors do not.
bool stream_in_sync_after(DecodeStatus status);

struct Limits {
  size_t max_payload_bytes = 64u << 20;  // 64 MiB: ~4.2 M points of 4 floats
  size_t max_string_bytes = 1u << 20;    // any one string (token, reason, JSON, message)
};
constexpr double kQuaternionNormTolerance = 1e-3;  // quaternions are normalised after the check

struct Header {
  uint16_t version = kProtocolVersion;
  uint16_t type = 0;
  uint32_t payload_bytes = 0;
};

// Checks the first kHeaderBytes of `data`: magic, version, known type, length within limits.
DecodeStatus decode_header(const uint8_t* data, size_t size, const Limits& limits, Header& out);

// ---- messages -----------------------------------------------------------------------------

struct HelloRequest {
  std::string token;
};
struct HelloOkReply {};
struct PingRequest {
  uint64_t nonce = 0;
};
struct PongReply {
  uint64_t nonce = 0;
};
struct InfoRequest {};

struct InfoReply {
  uint16_t protocol_version = kProtocolVersion;
  std::string map_name;
  uint64_t segment_count = 0;
  Eigen::Vector3d extent_min = Eigen::Vector3d::Zero();  // bbox of segment centroids (map frame)
  Eigen::Vector3d extent_max = Eigen::Vector3d::Zero();
  std::string parameters_json;  // the map's PipelineConfig (io::to_json)
};

// Flag bits of LocalizeRequest::flags.
constexpr uint32_t kFlagHasPrior = 1u << 0;
// The points are voxel centroids of the map's voxel grid (docs/protocol.md 5.4): the server
// skips its voxel grid.
constexpr uint32_t kFlagVoxelized = 1u << 1;
// Revision 2 (docs/protocol.md 8): the prior's heading tolerance follows the points.
constexpr uint32_t kFlagPriorHeading = 1u << 2;
// Revision 5: the reply carries a RefusalCode (docs/protocol.md 6.4). A server of revision 4
// or older answers MALFORMED to it.
constexpr uint32_t kFlagRefusalCode = 1u << 3;
// Revision 6: the reply carries a ReplyDetail block (docs/protocol.md 6.4).
constexpr uint32_t kFlagDetail = 1u << 4;
// Revision 8: the vehicle's newest scans follow (docs/protocol.md 5.4): the server refines the
// answer to them, the sensor's pose now rather than the drift-warped whole cloud's.
constexpr uint32_t kFlagNewestScans = 1u << 5;
// Revision 11: track on the surface layer first (docs/protocol.md 5.4); needs bits 0 and 5.
constexpr uint32_t kFlagTrack = 1u << 6;
constexpr uint32_t kKnownFlags =
    kFlagHasPrior | kFlagVoxelized | kFlagPriorHeading | kFlagRefusalCode | kFlagDetail | kFlagNewestScans | kFlagTrack;

struct LocalizeRequest {
  uint64_t request_id = 0;
  uint32_t flags = 0;
  // The sensor in the vehicle's local (odometry) frame: the server crops the local cylinder
  // around its position.
  Eigen::Vector3d sensor_position_local = Eigen::Vector3d::Zero();
  Eigen::Quaterniond sensor_orientation_local = Eigen::Quaterniond::Identity();
  // Used when flags & kFlagHasPrior: a guess of T_map_local and how far (metres, horizontal
  // and vertical alike) the sensor's map position may be from where that guess puts it.
  Pose3d T_map_local_prior = Pose3d::Identity();
  double prior_radius_m = 0.0;
  // Sent only with kFlagPriorHeading (after the points); without it the server assumes 10 deg.
  double prior_heading_tolerance_deg = 10.0;
  uint32_t point_stride = 4;  // floats per point on the wire: 3 (x y z) or 4 (x y z intensity)
  PointCloud points;          // local frame; intensity 0 when the stride is 3
  // Sent only with kFlagNewestScans: the points of the scans of the last few metres (local
  // frame, x y z; raw or thinned), a subset in time of the cloud above.
  PointCloud newest_points;
};

// ---- LOCALIZE_SEGMENTS (revision 3, docs/protocol.md 5.5) ----------------------------------
// The vehicle segments and describes its local cloud itself (with the map's parameters, from
// INFO_REPLY) and sends the segments: centroids and eigenvalue features as f32, ESF histograms
// as u16 mantissas of a power-of-two scale, points as i16 offsets from the centroid in
// power-of-two steps, the finest that holds the segment (a point moves by less than 1/32767 of
// the segment's reach: 0.07 mm on a car, 1 mm on a facade 32 m long).
constexpr uint32_t kSegmentsFlagHasPrior = 1u << 0;     // as LOCALIZE bit 0 (heading tolerance always sent)
constexpr uint32_t kSegmentsFlagEsf = 1u << 1;          // every segment carries its ESF histogram
constexpr uint32_t kSegmentsFlagRefusalCode = 1u << 2;  // revision 5, as LOCALIZE bit 3
constexpr uint32_t kSegmentsFlagDetail = 1u << 3;       // revision 6, as LOCALIZE bit 4
constexpr uint32_t kSegmentsFlagNewestScans = 1u << 4;  // revision 10, as LOCALIZE bit 5
// Revision 11: track on the surface layer (docs/protocol.md 5.5); needs bits 0 and 4; the
// segments may then carry no points.
constexpr uint32_t kSegmentsFlagTrack = 1u << 5;
constexpr uint32_t kKnownSegmentsFlags = kSegmentsFlagHasPrior | kSegmentsFlagEsf | kSegmentsFlagRefusalCode |
                                         kSegmentsFlagDetail | kSegmentsFlagNewestScans | kSegmentsFlagTrack;
constexpr int kPointStepExponentMin = -16;  // finest point step 2^-16 m (15 um)
constexpr int kPointStepExponentMax = 10;
constexpr int kEsfExponentMin = -64;
constexpr int kEsfExponentMax = 0;

struct LocalizeSegmentsRequest {
  uint64_t request_id = 0;
  uint32_t flags = 0;
  Eigen::Vector3d sensor_position_local = Eigen::Vector3d::Zero();
  Eigen::Quaterniond sensor_orientation_local = Eigen::Quaterniond::Identity();
  Pose3d T_map_local_prior = Pose3d::Identity();  // used with kSegmentsFlagHasPrior
  double prior_radius_m = 0.0;
  double prior_heading_tolerance_deg = 10.0;
  // segments_digest() of the parameters the segments were computed with.
  uint64_t parameters_digest = 0;
  // Query (local) frame. Encoding sends centroid, eigen, ESF (with kSegmentsFlagEsf) and
  // points; ids and labels are not sent (decoded segments are numbered 0..M-1).
  Segments segments;
  // Sent only with kSegmentsFlagNewestScans: as LocalizeRequest::newest_points (x y z, f32).
  PointCloud newest_points;
};

// Names the parameters a vehicle's segments were made with: FNV-1a (64 bit) of the
// segmentation code's version (core kSegmentCodeVersion) and INFO_REPLY's parameters JSON,
// byte for byte. The server computes it from the JSON it sends in INFO_REPLY.
uint64_t segments_digest(const std::string& parameters_json);

// Bytes of the quantised encoding that one segment's points take (header excluded): 6 per point.
constexpr size_t kBytesPerSegmentPoint = 6;

enum class LocalizeStatus : uint16_t { kLocalized = 0, kNotLocalized = 1, kOutsidePrior = 2 };
const char* to_string(LocalizeStatus status);

// Why not localized, on the wire (revision 5, docs/protocol.md 6.4). Sent only to a request
// that sets its refusal-code bit; kNone otherwise. A decoded reply may hold a value this build
// does not name (a later revision's): to_string gives "UNKNOWN".
enum class RefusalCode : uint16_t {
  kNone = 0,
  kEmptyMap = 1,
  kTooFewSegments = 2,
  kNoConsistentMatches = 3,
  kOutsidePrior = 4,
  kLowSupport = 5,
  kAmbiguous = 6,
  kSurfacesDisagree = 7,
  kLowConfidence = 8,
  kOffMap = 9,                // revision 9: the vehicle's newest scans do not lie on the map at the answer
  kNewestScansDisagree = 10,  // revision 9: they do, but settle away from the answer
  kTrackingLost = 11,         // revision 11: a tracking request (segments bit 5) without points did not register
};
const char* to_string(RefusalCode code);

struct ModuleTimingsMs {
  float voxel = 0, ground = 0, segment = 0, describe = 0, retrieve = 0, classify = 0, verify = 0, refine = 0, total = 0,
        server_total = 0;  // server_total: receipt to reply, crop included
};
constexpr size_t kTimingCount = 10;

// Revision 6 (docs/protocol.md 6.4): what the localizer measured beyond the pose, sent only to
// a request that sets its detail bit. The block carries its own length, so later revisions
// append fields to it and a decoder skips those it does not know.
struct ReplyDetail {
  // How far the whole local cloud's pose and its recent window's differ at the sensor (the
  // vehicle odometry's warp over the cloud), and the window's query points (0: no window).
  float window_warp_m = 0.f, window_warp_deg = 0.f;
  uint32_t window_points = 0;
  // Revision 7: what answered and how uncertain it is. Absent in a revision-6 server's reply.
  struct Estimate {
    uint8_t method = 0;  // ReplyMethod's values; others: a method this revision cannot name
    // The upper triangle, row by row, of the sensor pose's 6x6 covariance (docs/protocol.md
    // 6.4): rotation (rad, map axes through the sensor), then position (m, map). All zero: none.
    std::array<float, 21> covariance_upper{};
  };
  std::optional<Estimate> estimate;
};
constexpr size_t kReplyDetailBytes = 12;           // revision 6's fields
constexpr size_t kReplyDetailEstimateBytes = 100;  // with revision 7's
// 2: revision 11; 3: revision 12 (a cold start: the surface layer around a recognised place)
enum class ReplyMethod : uint8_t { kSegments = 0, kRegistration = 1, kSurfaces = 2, kPlaces = 3 };
const char* to_string(ReplyMethod method);
// The covariance as a matrix, and back (the upper triangle; the matrix is symmetric).
Eigen::Matrix<double, 6, 6> covariance_matrix(const std::array<float, 21>& upper);
std::array<float, 21> covariance_upper(const Eigen::Matrix<double, 6, 6>& covariance);

struct LocalizeReply {
  uint64_t request_id = 0;
  LocalizeStatus status = LocalizeStatus::kNotLocalized;
  RefusalCode refusal = RefusalCode::kNone;  // with the request's refusal-code bit (revision 5)
  std::string reason;                        // empty when localized
  Pose3d T_map_local = Pose3d::Identity();   // on the wire: quaternion w x y z + translation
  uint32_t inliers = 0;
  float confidence = 0.f;
  uint32_t support = 0;
  std::vector<uint64_t> matched_segment_ids;  // map segment ids of the inliers
  ModuleTimingsMs timings;
  std::optional<ReplyDetail> detail;  // with the request's detail bit (revision 6)
};

struct ErrorReply {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;
};

// Each encode returns a whole frame (header + payload).
std::vector<uint8_t> encode(const HelloRequest& m);
std::vector<uint8_t> encode(const HelloOkReply& m);
std::vector<uint8_t> encode(const PingRequest& m);
std::vector<uint8_t> encode(const PongReply& m);
std::vector<uint8_t> encode(const InfoRequest& m);
std::vector<uint8_t> encode(const InfoReply& m);
std::vector<uint8_t> encode(const LocalizeRequest& m);
std::vector<uint8_t> encode(const LocalizeSegmentsRequest& m);
std::vector<uint8_t> encode(const LocalizeReply& m);
std::vector<uint8_t> encode(const ErrorReply& m);

// Each decode reads one payload (without the header).
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, HelloRequest& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, HelloOkReply& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, PingRequest& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, PongReply& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, InfoRequest& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, InfoReply& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, LocalizeRequest& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, LocalizeSegmentsRequest& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, LocalizeReply& out);
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, ErrorReply& out);

// A whole frame in one buffer: decodes the header, checks that exactly header + payload bytes
// are present (kIncomplete if fewer, kTrailingBytes if more) and decodes the payload as M,
// refusing a frame of another type with kUnknownType.
template <typename M>
DecodeStatus decode_frame(const std::vector<uint8_t>& frame, const Limits& limits, M& out);

MessageType type_of(const HelloRequest&);
MessageType type_of(const HelloOkReply&);
MessageType type_of(const PingRequest&);
MessageType type_of(const PongReply&);
MessageType type_of(const InfoRequest&);
MessageType type_of(const InfoReply&);
MessageType type_of(const LocalizeRequest&);
MessageType type_of(const LocalizeSegmentsRequest&);
MessageType type_of(const LocalizeReply&);
MessageType type_of(const ErrorReply&);

template <typename M>
DecodeStatus decode_frame(const std::vector<uint8_t>& frame, const Limits& limits, M& out) {
  Header header;
  const DecodeStatus s = decode_header(frame.data(), frame.size(), limits, header);
  if (s != DecodeStatus::kOk) return s;
  if (header.type != static_cast<uint16_t>(type_of(out))) return DecodeStatus::kUnknownType;
  const size_t total = kHeaderBytes + header.payload_bytes;
  if (frame.size() < total) return DecodeStatus::kIncomplete;
  if (frame.size() > total) return DecodeStatus::kTrailingBytes;
  return decode(frame.data() + kHeaderBytes, header.payload_bytes, limits, out);
}

}  // namespace api
}  // namespace segmatch
