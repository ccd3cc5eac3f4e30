// The SGMQ codec: every message round-trips exactly; every malformed input is refused with
// the right status, without throwing or reading outside the buffer.
#include "segmatch/api/protocol.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

using namespace segmatch;
using namespace segmatch::api;

namespace {

const Limits kLimits;

template <typename M>
M round_trip(const M& in) {
  M out;
  const std::vector<uint8_t> frame = encode(in);
  EXPECT_EQ(decode_frame(frame, kLimits, out), DecodeStatus::kOk);
  return out;
}

Pose3d some_pose() {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.2, -0.3, 1.0).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(1234.5, -87.25, 3.125);
  return T;
}

LocalizeRequest some_request(uint32_t stride = 4) {
  LocalizeRequest r;
  r.request_id = 0x0102030405060708ull;
  r.flags = kFlagHasPrior;
  r.sensor_position_local = Eigen::Vector3d(10.5, -3.25, 1.73);
  r.sensor_orientation_local = Eigen::Quaterniond(Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitZ()));
  r.T_map_local_prior = some_pose();
  r.prior_radius_m = 25.0;
  r.point_stride = stride;
  for (int i = 0; i < 100; ++i)
    r.points.push_back(Point{i * 0.5f, -i * 0.25f, 1.f + i * 0.01f, stride == 4 ? i / 100.f : 0.f});
  return r;
}

// Byte offset of a LOCALIZE field inside the frame (docs/protocol.md 5.4).
constexpr size_t kPayload = kHeaderBytes;
constexpr size_t kOffFlags = kPayload + 8, kOffPosition = kPayload + 12, kOffQuat = kPayload + 36,
                 kOffPriorQuat = kPayload + 68, kOffRadius = kPayload + 124, kOffCount = kPayload + 132,
                 kOffStride = kPayload + 136, kOffPoints = kPayload + 140;

void put_f64(std::vector<uint8_t>& b, size_t at, double v) { std::memcpy(&b[at], &v, 8); }
void put_f32(std::vector<uint8_t>& b, size_t at, float v) { std::memcpy(&b[at], &v, 4); }
void put_u32(std::vector<uint8_t>& b, size_t at, uint32_t v) { std::memcpy(&b[at], &v, 4); }

DecodeStatus decode_request(const std::vector<uint8_t>& frame, const Limits& limits = kLimits) {
  LocalizeRequest out;
  return decode_frame(frame, limits, out);
}

}  // namespace

TEST(Protocol, HeaderIsMagicVersionTypeLengthLittleEndian) {
  const std::vector<uint8_t> f = encode(PingRequest{0x1122334455667788ull});
  ASSERT_EQ(f.size(), kHeaderBytes + 8);
  EXPECT_EQ(std::string(f.begin(), f.begin() + 4), "SGMQ");
  EXPECT_EQ(f[4], 1);
  EXPECT_EQ(f[5], 0);  // version 1
  EXPECT_EQ(f[6], 0x02);
  EXPECT_EQ(f[7], 0x00);  // PING
  EXPECT_EQ(f[8], 8);
  EXPECT_EQ(f[11], 0);  // payload length 8
  EXPECT_EQ(f[12], 0x88);
  EXPECT_EQ(f[19], 0x11);  // nonce, little-endian
}

TEST(Protocol, SmallMessagesRoundTrip) {
  EXPECT_EQ(round_trip(HelloRequest{"s3cret\0x"}).token, std::string("s3cret\0x"));
  round_trip(HelloOkReply{});
  round_trip(InfoRequest{});
  EXPECT_EQ(round_trip(PingRequest{42}).nonce, 42u);
  EXPECT_EQ(round_trip(PongReply{~0ull}).nonce, ~0ull);
  const ErrorReply e = round_trip(ErrorReply{ErrorCode::kAuthFailed, "wrong token"});
  EXPECT_EQ(e.code, ErrorCode::kAuthFailed);
  EXPECT_EQ(e.message, "wrong token");
}

TEST(Protocol, InfoReplyRoundTrips) {
  InfoReply in;
  in.map_name = "city-00";
  in.segment_count = 12345;
  in.extent_min = Eigen::Vector3d(-100.5, -20, -3);
  in.extent_max = Eigen::Vector3d(400, 250.25, 12);
  in.parameters_json = R"({"preset": "kitti-hdl64"})";
  const InfoReply out = round_trip(in);
  EXPECT_EQ(out.protocol_version, kProtocolVersion);
  EXPECT_EQ(out.map_name, in.map_name);
  EXPECT_EQ(out.segment_count, in.segment_count);
  EXPECT_EQ(out.extent_min, in.extent_min);
  EXPECT_EQ(out.extent_max, in.extent_max);
  EXPECT_EQ(out.parameters_json, in.parameters_json);
}

TEST(Protocol, LocalizeRequestRoundTripsWithBothStrides) {
  for (uint32_t stride : {3u, 4u}) {
    const LocalizeRequest in = some_request(stride);
    const std::vector<uint8_t> frame = encode(in);
    EXPECT_EQ(frame.size(), kHeaderBytes + 140 + in.points.size() * stride * 4);
    const LocalizeRequest out = round_trip(in);
    EXPECT_EQ(out.request_id, in.request_id);
    EXPECT_EQ(out.flags, in.flags);
    EXPECT_EQ(out.sensor_position_local, in.sensor_position_local);
    EXPECT_NEAR(out.sensor_orientation_local.angularDistance(in.sensor_orientation_local), 0.0, 1e-12);
    EXPECT_TRUE(out.T_map_local_prior.isApprox(in.T_map_local_prior, 1e-12));
    EXPECT_EQ(out.prior_radius_m, in.prior_radius_m);
    EXPECT_EQ(out.point_stride, stride);
    ASSERT_EQ(out.points.size(), in.points.size());
    for (size_t i = 0; i < in.points.size(); ++i) {
      EXPECT_EQ(out.points[i].x, in.points[i].x);
      EXPECT_EQ(out.points[i].z, in.points[i].z);
      EXPECT_EQ(out.points[i].intensity, in.points[i].intensity);
    }
  }
}

TEST(Protocol, LocalizeReplyRoundTrips) {
  LocalizeReply in;
  in.request_id = 77;
  in.status = LocalizeStatus::kOutsidePrior;
  in.reason = "localized 40 m from the prior";
  in.T_map_local = some_pose();
  in.inliers = 9, in.support = 14, in.confidence = 0.8125f;
  in.matched_segment_ids = {3, 99, 1ull << 40};
  in.timings.voxel = 1.5f, in.timings.total = 80.25f, in.timings.server_total = 81.f;
  in.refusal = RefusalCode::kOutsidePrior;
  const LocalizeReply out = round_trip(in);
  EXPECT_EQ(out.request_id, 77u);
  EXPECT_EQ(out.status, LocalizeStatus::kOutsidePrior);
  EXPECT_EQ(out.refusal, RefusalCode::kOutsidePrior);
  EXPECT_EQ(out.reason, in.reason);
  EXPECT_TRUE(out.T_map_local.isApprox(in.T_map_local, 1e-12));
  EXPECT_EQ(out.inliers, 9u);
  EXPECT_EQ(out.support, 14u);
  EXPECT_EQ(out.confidence, 0.8125f);
  EXPECT_EQ(out.matched_segment_ids, in.matched_segment_ids);
  EXPECT_EQ(out.timings.voxel, 1.5f);
  EXPECT_EQ(out.timings.total, 80.25f);
  EXPECT_EQ(out.timings.server_total, 81.f);
}

// Revision 5: the former reserved field of LOCALIZE_REPLY is the refusal code. Every value
// decodes (a later revision's code too) and re-encodes to the same bytes.
TEST(Protocol, LocalizeReplyCarriesAnyRefusalCode) {
  LocalizeReply in;
  in.request_id = 5;
  in.reason = "ambiguous";
  for (const uint16_t code : {uint16_t(0), uint16_t(6), uint16_t(8), uint16_t(999)}) {
    in.refusal = static_cast<RefusalCode>(code);
    const std::vector<uint8_t> f = encode(in);
    EXPECT_EQ(f[kHeaderBytes + 10] | f[kHeaderBytes + 11] << 8, code) << "offset 10, u16 little-endian";
    LocalizeReply out;
    ASSERT_EQ(decode_frame(f, kLimits, out), DecodeStatus::kOk) << code;
    EXPECT_EQ(static_cast<uint16_t>(out.refusal), code);
    EXPECT_EQ(encode(out), f);
  }
  EXPECT_STREQ(to_string(RefusalCode::kAmbiguous), "AMBIGUOUS");
  EXPECT_STREQ(to_string(static_cast<RefusalCode>(999)), "UNKNOWN");
}

TEST(Protocol, RejectsBadMagicVersionTypeAndSize) {
  std::vector<uint8_t> f = encode(PingRequest{1});
  Header h;
  std::vector<uint8_t> bad = f;
  bad[0] = 'X';
  EXPECT_EQ(decode_header(bad.data(), bad.size(), kLimits, h), DecodeStatus::kBadMagic);
  bad = f, bad[4] = 2;
  EXPECT_EQ(decode_header(bad.data(), bad.size(), kLimits, h), DecodeStatus::kBadVersion);
  bad = f, bad[6] = 0x7F;
  EXPECT_EQ(decode_header(bad.data(), bad.size(), kLimits, h), DecodeStatus::kUnknownType);
  EXPECT_EQ(h.payload_bytes, 8u) << "header filled so the payload can be skipped";
  EXPECT_EQ(decode_header(f.data(), 11, kLimits, h), DecodeStatus::kIncomplete);
  EXPECT_EQ(decode_header(nullptr, 0, kLimits, h), DecodeStatus::kIncomplete);
  Limits small;
  small.max_payload_bytes = 1000;
  const std::vector<uint8_t> big = encode(some_request());
  EXPECT_EQ(decode_header(big.data(), big.size(), small, h), DecodeStatus::kTooLarge);
  EXPECT_FALSE(stream_in_sync_after(DecodeStatus::kBadMagic));
  EXPECT_FALSE(stream_in_sync_after(DecodeStatus::kTooLarge));
  EXPECT_TRUE(stream_in_sync_after(DecodeStatus::kBadPointCount));
}

TEST(Protocol, RejectsEveryTruncationAndTrailingBytes) {
  const std::vector<uint8_t> frames[] = {encode(some_request()), encode(InfoReply{}), encode(ErrorReply{}),
                                         encode(PingRequest{}), encode(HelloRequest{"abc"})};
  for (const std::vector<uint8_t>& full : frames) {
    Header h;
    ASSERT_EQ(decode_header(full.data(), full.size(), kLimits, h), DecodeStatus::kOk);
    // Every shorter payload (header length adjusted, so only the payload lies) is refused.
    for (size_t n = 0; n < h.payload_bytes; n += (n < 200 ? 1 : 97)) {
      std::vector<uint8_t> cut(full.begin(), full.begin() + kHeaderBytes + n);
      put_u32(cut, 8, static_cast<uint32_t>(n));
      const uint8_t* p = cut.data() + kHeaderBytes;
      DecodeStatus s = DecodeStatus::kOk;
      switch (static_cast<MessageType>(h.type)) {
        case MessageType::kLocalize: {
          LocalizeRequest m;
          s = decode(p, n, kLimits, m);
          break;
        }
        case MessageType::kInfoReply: {
          InfoReply m;
          s = decode(p, n, kLimits, m);
          break;
        }
        case MessageType::kError: {
          ErrorReply m;
          s = decode(p, n, kLimits, m);
          break;
        }
        case MessageType::kPing: {
          PingRequest m;
          s = decode(p, n, kLimits, m);
          break;
        }
        default: {
          HelloRequest m;
          s = decode(p, n, kLimits, m);
          break;
        }
      }
      EXPECT_NE(s, DecodeStatus::kOk) << "type " << h.type << " cut to " << n;
    }
    std::vector<uint8_t> longer = full;
    longer.push_back(0);
    PingRequest ping;
    if (h.type == static_cast<uint16_t>(MessageType::kPing)) {
      EXPECT_EQ(decode_frame(longer, kLimits, ping), DecodeStatus::kTrailingBytes);
    }
  }
  PingRequest ping;
  std::vector<uint8_t> f = encode(PingRequest{5});
  f.push_back(0);
  put_u32(f, 8, 9);  // the header admits the extra byte: the payload has trailing bytes
  EXPECT_EQ(decode_frame(f, kLimits, ping), DecodeStatus::kTrailingBytes);
}

TEST(Protocol, RejectsPointCountDisagreeingWithLength) {
  std::vector<uint8_t> f = encode(some_request());
  put_u32(f, kOffCount, 101);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  put_u32(f, kOffCount, 0xFFFFFFFFu);  // would overflow 32-bit arithmetic
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  f = encode(some_request());
  put_u32(f, kOffStride, 3);  // 100 points of 4 floats read as stride 3
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  put_u32(f, kOffStride, 5);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadStride);
}

TEST(Protocol, RejectsNonFiniteValues) {
  const float bad_floats[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                              -std::numeric_limits<float>::infinity()};
  for (float v : bad_floats) {
    for (size_t field = 0; field < 4; ++field) {  // x, y, z, intensity of point 57
      std::vector<uint8_t> f = encode(some_request());
      put_f32(f, kOffPoints + (57 * 4 + field) * 4, v);
      EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite) << "field " << field;
    }
  }
  std::vector<uint8_t> f = encode(some_request());
  put_f64(f, kOffPosition + 8, std::nan(""));
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = encode(some_request());
  put_f64(f, kOffRadius, INFINITY);
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = encode(some_request());
  put_f64(f, kOffRadius, -1.0);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  f = encode(some_request());
  put_f64(f, kOffPriorQuat + 32 + 16, std::nan(""));  // prior translation z
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
}

TEST(Protocol, RejectsBadQuaternionsAndAcceptsSlightlyOffOnes) {
  std::vector<uint8_t> f = encode(some_request());
  for (int i = 0; i < 4; ++i) put_f64(f, kOffQuat + 8 * i, 0.0);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadQuaternion);
  f = encode(some_request());
  put_f64(f, kOffPriorQuat, 2.0);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadQuaternion);
  f = encode(some_request());
  put_f64(f, kOffQuat, std::nan(""));
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = encode(some_request());
  for (int i = 0; i < 4; ++i) put_f64(f, kOffQuat + 8 * i, i == 0 ? 1.0005 : 0.0);  // within tolerance
  LocalizeRequest out;
  ASSERT_EQ(decode_frame(f, kLimits, out), DecodeStatus::kOk);
  EXPECT_NEAR(out.sensor_orientation_local.norm(), 1.0, 1e-12) << "normalised";
}

TEST(Protocol, RejectsReservedFlagsAndOverlongStrings) {
  std::vector<uint8_t> f = encode(some_request());
  put_u32(f, kOffFlags, 0x80000001u);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  put_u32(f, kOffFlags, 1u << 6);  // the first bit not defined by revision 8 (docs/protocol.md 8)
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  put_u32(f, kOffFlags, kFlagRefusalCode);  // revision 5's bit 3, no trailer
  EXPECT_EQ(decode_request(f), DecodeStatus::kOk);
  put_u32(f, kOffFlags, kFlagPriorHeading);  // bit 2 announces 8 more bytes that are not there
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  put_u32(f, kOffFlags, kFlagHasPrior | kFlagVoxelized);
  LocalizeRequest both;
  ASSERT_EQ(decode_frame(f, kLimits, both), DecodeStatus::kOk);
  EXPECT_EQ(both.flags, kFlagHasPrior | kFlagVoxelized);
  Limits limits;
  limits.max_string_bytes = 4;
  HelloRequest hello;
  EXPECT_EQ(decode_frame(encode(HelloRequest{"12345"}), limits, hello), DecodeStatus::kBadField);
  EXPECT_EQ(decode_frame(encode(HelloRequest{"1234"}), limits, hello), DecodeStatus::kOk);
  std::vector<uint8_t> e = encode(ErrorReply{ErrorCode::kInternal, "x"});
  put_u32(e, kHeaderBytes + 2, 0xFFFFFFF0u);  // string length over the limit
  ErrorReply err;
  EXPECT_EQ(decode_frame(e, kLimits, err), DecodeStatus::kBadField);
  put_u32(e, kHeaderBytes + 2, 100);  // within the limit but beyond the payload
  EXPECT_EQ(decode_frame(e, kLimits, err), DecodeStatus::kTruncated);
}

TEST(Protocol, DecodeFrameRefusesAnotherMessageType) {
  PingRequest ping;
  EXPECT_EQ(decode_frame(encode(PongReply{1}), kLimits, ping), DecodeStatus::kUnknownType);
  std::vector<uint8_t> f = encode(PingRequest{1});
  f.pop_back();
  EXPECT_EQ(decode_frame(f, kLimits, ping), DecodeStatus::kIncomplete);
}

TEST(Protocol, RandomBytesNeverCrashTheDecoders) {
  uint64_t state = 12345;
  auto next = [&] {
    return static_cast<uint8_t>((state = state * 6364136223846793005ull + 1442695040888963407ull) >> 56);
  };
  const std::vector<uint8_t> base = encode(some_request());
  size_t accepted = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    std::vector<uint8_t> f = base;
    for (int k = 0; k < 1 + trial % 8; ++k) f[kHeaderBytes + next() * 256u % (f.size() - kHeaderBytes)] = next();
    f.resize(kHeaderBytes + (f.size() - kHeaderBytes) * (trial % 5 == 0 ? next() : 255) / 255);
    put_u32(f, 8, static_cast<uint32_t>(f.size() - kHeaderBytes));
    LocalizeRequest req;
    LocalizeReply rep;
    InfoReply info;
    accepted += decode_frame(f, kLimits, req) == DecodeStatus::kOk;
    decode(f.data() + kHeaderBytes, f.size() - kHeaderBytes, kLimits, rep);
    decode(f.data() + kHeaderBytes, f.size() - kHeaderBytes, kLimits, info);
  }
  EXPECT_LT(accepted, 3000u);
}

// Revision 2: the heading tolerance travels after the points behind flag bit 2 and round-trips;
// a bad one is refused by name.
TEST(Protocol, HeadingToleranceTravelsBehindItsFlagBit) {
  LocalizeRequest r = some_request();
  r.flags |= kFlagPriorHeading;
  r.prior_heading_tolerance_deg = 4.5;
  const std::vector<uint8_t> f = encode(r);
  EXPECT_EQ(f.size(), encode(some_request()).size() + 8);
  const LocalizeRequest back = round_trip(r);
  EXPECT_EQ(back.flags, r.flags);
  EXPECT_EQ(back.prior_heading_tolerance_deg, 4.5);
  EXPECT_EQ(back.points.size(), r.points.size());
  std::vector<uint8_t> bad = f;
  put_f64(bad, bad.size() - 8, -1.0);
  EXPECT_EQ(decode_request(bad), DecodeStatus::kBadField);
  put_f64(bad, bad.size() - 8, std::numeric_limits<double>::infinity());
  EXPECT_EQ(decode_request(bad), DecodeStatus::kNonFinite);
  // Without the bit, the field is not on the wire and decodes to its default.
  EXPECT_EQ(round_trip(some_request()).prior_heading_tolerance_deg, 10.0);
}

// Revision 8: the newest scans travel last, behind flag bit 5, after the heading tolerance when
// both are set; their count must match the payload, their coordinates be finite.
TEST(Protocol, NewestScansTravelBehindTheirFlagBit) {
  LocalizeRequest r = some_request();
  r.flags |= kFlagNewestScans | kFlagPriorHeading;
  r.prior_heading_tolerance_deg = 4.5;
  r.newest_points = {{1.5f, -2.f, 0.25f, 9.f}, {3.f, 4.f, -0.5f, 0.f}};
  const std::vector<uint8_t> f = encode(r);
  EXPECT_EQ(f.size(), encode(some_request()).size() + 8 + 4 + 2 * 12);
  const LocalizeRequest back = round_trip(r);
  EXPECT_EQ(back.prior_heading_tolerance_deg, 4.5);
  ASSERT_EQ(back.newest_points.size(), 2u);
  EXPECT_EQ(back.newest_points[0].x, 1.5f);
  EXPECT_EQ(back.newest_points[0].intensity, 0.f) << "x y z only on the wire";
  EXPECT_EQ(back.newest_points[1].z, -0.5f);
  EXPECT_EQ(back.points.size(), r.points.size());
  auto decode_payload = [](std::vector<uint8_t> frame) {
    LocalizeRequest out;
    return decode(frame.data() + kHeaderBytes, frame.size() - kHeaderBytes, kLimits, out);
  };
  std::vector<uint8_t> shorter = f;
  shorter.resize(f.size() - 12);  // one newest point fewer than counted
  EXPECT_EQ(decode_payload(shorter), DecodeStatus::kBadPointCount);
  std::vector<uint8_t> longer = f;
  longer.resize(f.size() + 4, 0);
  EXPECT_EQ(decode_payload(longer), DecodeStatus::kBadPointCount);
  std::vector<uint8_t> no_count = encode(some_request());
  put_u32(no_count, kOffFlags, kFlagNewestScans);  // the bit, but not even a count
  EXPECT_EQ(decode_payload(no_count), DecodeStatus::kBadPointCount);
  std::vector<uint8_t> nan = f;
  nan[nan.size() - 2] = 0xC0, nan[nan.size() - 1] = 0x7F;  // the last point's z: a float NaN (LE 00 00 C0 7F)
  nan[nan.size() - 4] = nan[nan.size() - 3] = 0;
  EXPECT_EQ(decode_payload(nan), DecodeStatus::kNonFinite);
  r.newest_points.clear();  // zero newest points: the count alone
  EXPECT_EQ(round_trip(r).newest_points.size(), 0u);
  // Without the bit nothing follows the points, whatever the field holds.
  LocalizeRequest without = some_request();
  without.newest_points = {{1.f, 2.f, 3.f, 0.f}};
  EXPECT_EQ(encode(without), encode(some_request()));
}
