// Header, names, status mapping and the small messages (HELLO, PING, INFO, ERROR).
// LOCALIZE and LOCALIZE_REPLY are in localize_codec.cpp.
#include "segmatch/api/protocol.h"

#include "codec_util.h"

#include <cstring>

namespace segmatch {
namespace api {

bool is_known_type(uint16_t type) {
  switch (static_cast<MessageType>(type)) {
    case MessageType::kHello:
    case MessageType::kPing:
    case MessageType::kInfo:
    case MessageType::kLocalize:
    case MessageType::kLocalizeSegments:
    case MessageType::kHelloOk:
    case MessageType::kPong:
    case MessageType::kInfoReply:
    case MessageType::kLocalizeReply:
    case MessageType::kError: return true;
  }
  return false;
}

const char* to_string(MessageType type) {
  switch (type) {
    case MessageType::kHello: return "HELLO";
    case MessageType::kPing: return "PING";
    case MessageType::kInfo: return "INFO";
    case MessageType::kLocalize: return "LOCALIZE";
    case MessageType::kLocalizeSegments: return "LOCALIZE_SEGMENTS";
    case MessageType::kHelloOk: return "HELLO_OK";
    case MessageType::kPong: return "PONG";
    case MessageType::kInfoReply: return "INFO_REPLY";
    case MessageType::kLocalizeReply: return "LOCALIZE_REPLY";
    case MessageType::kError: return "ERROR";
  }
  return "UNKNOWN";
}

const char* to_string(DecodeStatus status) {
  switch (status) {
    case DecodeStatus::kOk: return "ok";
    case DecodeStatus::kIncomplete: return "incomplete frame";
    case DecodeStatus::kBadMagic: return "bad magic (not an SGMQ frame)";
    case DecodeStatus::kBadVersion: return "unsupported protocol version";
    case DecodeStatus::kUnknownType: return "unknown or unexpected message type";
    case DecodeStatus::kTooLarge: return "payload over the size limit";
    case DecodeStatus::kTruncated: return "payload truncated";
    case DecodeStatus::kTrailingBytes: return "trailing bytes after the payload's fields";
    case DecodeStatus::kBadPointCount: return "point count disagrees with the payload length";
    case DecodeStatus::kBadStride: return "point stride must be 3 or 4 floats";
    case DecodeStatus::kNonFinite: return "NaN or Inf value";
    case DecodeStatus::kBadQuaternion: return "quaternion is not unit length";
    case DecodeStatus::kBadField: return "invalid field (reserved bits, string length or range)";
  }
  return "unknown decode status";
}

const char* to_string(LocalizeStatus status) {
  switch (status) {
    case LocalizeStatus::kLocalized: return "localized";
    case LocalizeStatus::kNotLocalized: return "not_localized";
    case LocalizeStatus::kOutsidePrior: return "outside_prior";
  }
  return "unknown";
}

const char* to_string(ReplyMethod method) {
  switch (method) {
    case ReplyMethod::kSegments: return "segments";
    case ReplyMethod::kRegistration: return "registration";
    case ReplyMethod::kSurfaces: return "surfaces";
    case ReplyMethod::kPlaces: return "places";
  }
  return "unknown";
}

Eigen::Matrix<double, 6, 6> covariance_matrix(const std::array<float, 21>& upper) {
  Eigen::Matrix<double, 6, 6> c;
  size_t k = 0;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) c(i, j) = c(j, i) = upper[k++];
  return c;
}

std::array<float, 21> covariance_upper(const Eigen::Matrix<double, 6, 6>& covariance) {
  std::array<float, 21> upper{};
  size_t k = 0;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) upper[k++] = static_cast<float>(covariance(i, j));
  return upper;
}

const char* to_string(RefusalCode code) {
  switch (code) {
    case RefusalCode::kNone: return "NONE";
    case RefusalCode::kEmptyMap: return "EMPTY_MAP";
    case RefusalCode::kTooFewSegments: return "TOO_FEW_SEGMENTS";
    case RefusalCode::kNoConsistentMatches: return "NO_CONSISTENT_MATCHES";
    case RefusalCode::kOutsidePrior: return "OUTSIDE_PRIOR";
    case RefusalCode::kLowSupport: return "LOW_SUPPORT";
    case RefusalCode::kAmbiguous: return "AMBIGUOUS";
    case RefusalCode::kSurfacesDisagree: return "SURFACES_DISAGREE";
    case RefusalCode::kLowConfidence: return "LOW_CONFIDENCE";
    case RefusalCode::kOffMap: return "OFF_MAP";
    case RefusalCode::kNewestScansDisagree: return "NEWEST_SCANS_DISAGREE";
    case RefusalCode::kTrackingLost: return "TRACKING_LOST";
  }
  return "UNKNOWN";
}

ErrorCode error_code_for(DecodeStatus status) {
  switch (status) {
    case DecodeStatus::kBadMagic: return ErrorCode::kBadMagic;
    case DecodeStatus::kBadVersion: return ErrorCode::kUnsupportedVersion;
    case DecodeStatus::kUnknownType: return ErrorCode::kUnknownType;
    case DecodeStatus::kTooLarge: return ErrorCode::kFrameTooLarge;
    case DecodeStatus::kBadPointCount:
    case DecodeStatus::kBadStride: return ErrorCode::kBadPointCount;
    case DecodeStatus::kNonFinite: return ErrorCode::kNonFinite;
    case DecodeStatus::kBadQuaternion: return ErrorCode::kBadQuaternion;
    default: return ErrorCode::kMalformed;
  }
}

bool stream_in_sync_after(DecodeStatus status) {
  return status != DecodeStatus::kBadMagic && status != DecodeStatus::kBadVersion &&
         status != DecodeStatus::kTooLarge && status != DecodeStatus::kIncomplete;
}

DecodeStatus decode_header(const uint8_t* data, size_t size, const Limits& limits, Header& out) {
  if (data == nullptr || size < kHeaderBytes) return DecodeStatus::kIncomplete;
  if (std::memcmp(data, kMagic.data(), kMagic.size()) != 0) return DecodeStatus::kBadMagic;
  wire::Reader r(data + 4, kHeaderBytes - 4);
  Header h;
  h.version = r.u16();
  h.type = r.u16();
  h.payload_bytes = r.u32();
  if (h.version != kProtocolVersion) return DecodeStatus::kBadVersion;
  if (h.payload_bytes > limits.max_payload_bytes) return DecodeStatus::kTooLarge;
  out = h;  // filled even for an unknown type, so the caller can skip its payload
  if (!is_known_type(h.type)) return DecodeStatus::kUnknownType;
  return DecodeStatus::kOk;
}

namespace detail {

std::vector<uint8_t> frame(MessageType type, wire::Writer& payload) {
  std::vector<uint8_t>& p = payload.bytes();
  wire::Writer w;
  w.reserve(kHeaderBytes + p.size());
  w.raw(kMagic.data(), kMagic.size());
  w.u16(kProtocolVersion);
  w.u16(static_cast<uint16_t>(type));
  w.u32(static_cast<uint32_t>(p.size()));
  w.raw(p.data(), p.size());
  return std::move(w.bytes());
}

DecodeStatus finish(const wire::Reader& r) {
  if (r.too_long()) return DecodeStatus::kBadField;
  if (r.failed()) return DecodeStatus::kTruncated;
  if (r.remaining() != 0) return DecodeStatus::kTrailingBytes;
  return DecodeStatus::kOk;
}

}  // namespace detail

MessageType type_of(const HelloRequest&) { return MessageType::kHello; }
MessageType type_of(const HelloOkReply&) { return MessageType::kHelloOk; }
MessageType type_of(const PingRequest&) { return MessageType::kPing; }
MessageType type_of(const PongReply&) { return MessageType::kPong; }
MessageType type_of(const InfoRequest&) { return MessageType::kInfo; }
MessageType type_of(const InfoReply&) { return MessageType::kInfoReply; }
MessageType type_of(const LocalizeRequest&) { return MessageType::kLocalize; }
MessageType type_of(const LocalizeSegmentsRequest&) { return MessageType::kLocalizeSegments; }
MessageType type_of(const LocalizeReply&) { return MessageType::kLocalizeReply; }
MessageType type_of(const ErrorReply&) { return MessageType::kError; }

std::vector<uint8_t> encode(const HelloRequest& m) {
  wire::Writer w;
  w.str(m.token);
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const HelloOkReply& m) {
  wire::Writer w;
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const PingRequest& m) {
  wire::Writer w;
  w.u64(m.nonce);
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const PongReply& m) {
  wire::Writer w;
  w.u64(m.nonce);
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const InfoRequest& m) {
  wire::Writer w;
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const InfoReply& m) {
  wire::Writer w;
  w.u16(m.protocol_version);
  w.u16(0);  // reserved
  w.str(m.map_name);
  w.u64(m.segment_count);
  for (int i = 0; i < 3; ++i) w.f64(m.extent_min[i]);
  for (int i = 0; i < 3; ++i) w.f64(m.extent_max[i]);
  w.str(m.parameters_json);
  return detail::frame(type_of(m), w);
}
std::vector<uint8_t> encode(const ErrorReply& m) {
  wire::Writer w;
  w.u16(static_cast<uint16_t>(m.code));
  w.str(m.message);
  return detail::frame(type_of(m), w);
}

DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, HelloRequest& out) {
  wire::Reader r(payload, size);
  HelloRequest m;
  m.token = r.str(limits.max_string_bytes);
  const DecodeStatus s = detail::finish(r);
  if (s == DecodeStatus::kOk) out = std::move(m);
  return s;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, HelloOkReply&) {
  return size == 0 ? DecodeStatus::kOk : DecodeStatus::kTrailingBytes;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, PingRequest& out) {
  wire::Reader r(payload, size);
  const uint64_t nonce = r.u64();
  const DecodeStatus s = detail::finish(r);
  if (s == DecodeStatus::kOk) out.nonce = nonce;
  return s;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, PongReply& out) {
  wire::Reader r(payload, size);
  const uint64_t nonce = r.u64();
  const DecodeStatus s = detail::finish(r);
  if (s == DecodeStatus::kOk) out.nonce = nonce;
  return s;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, InfoRequest&) {
  return size == 0 ? DecodeStatus::kOk : DecodeStatus::kTrailingBytes;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, InfoReply& out) {
  wire::Reader r(payload, size);
  InfoReply m;
  m.protocol_version = r.u16();
  const uint16_t reserved = r.u16();
  m.map_name = r.str(limits.max_string_bytes);
  m.segment_count = r.u64();
  for (int i = 0; i < 3; ++i) m.extent_min[i] = r.f64();
  for (int i = 0; i < 3; ++i) m.extent_max[i] = r.f64();
  m.parameters_json = r.str(limits.max_string_bytes);
  DecodeStatus s = detail::finish(r);
  if (s == DecodeStatus::kOk && reserved != 0) s = DecodeStatus::kBadField;
  if (s == DecodeStatus::kOk && !(m.extent_min.allFinite() && m.extent_max.allFinite())) s = DecodeStatus::kNonFinite;
  if (s == DecodeStatus::kOk) out = std::move(m);
  return s;
}
DecodeStatus decode(const uint8_t* payload, size_t size, const Limits& limits, ErrorReply& out) {
  wire::Reader r(payload, size);
  ErrorReply m;
  m.code = static_cast<ErrorCode>(r.u16());
  m.message = r.str(limits.max_string_bytes);
  const DecodeStatus s = detail::finish(r);
  if (s == DecodeStatus::kOk) out = std::move(m);
  return s;
}

}  // namespace api
}  // namespace segmatch
