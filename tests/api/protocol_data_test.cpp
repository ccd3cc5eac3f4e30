// tests/data/protocol/: one stored frame of every message type, written by this codec, that
// these tests and the Python client's (tests/python/test_protocol.py) both decode and re-encode
// byte for byte, so the two implementations cannot drift apart unnoticed. The field values are
// listed in tests/data/protocol/README.md; the Python tests check the same values.
//
// By default nothing is written: each file must decode with today's codec, re-encode to the same
// bytes, hold the listed values, and equal what the encoder writes for them. After a deliberate
// change of the protocol, rewrite the files (then review the diff and commit them with a note):
//   SEGMATCH_WRITE_PROTOCOL_DATA=1 build/tests/test_api --gtest_filter='ProtocolData.*'
// Frames of older revisions stay in tests/api/golden/ and are never rewritten.
#include "segmatch/api/protocol.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <set>
#include <string>
#include <vector>

using namespace segmatch;
using namespace segmatch::api;

namespace {

const std::string kDir = std::string(SEGMATCH_SOURCE_DIR) + "/tests/data/protocol/";
// Small, so the INFO_REPLY and the LOCALIZE_SEGMENTS digest (over these bytes) stay readable.
const std::string kParametersJson = R"({"voxel":{"leaf_m":0.1,"min_points_per_voxel":2}})";

bool writing() {
  const char* v = std::getenv("SEGMATCH_WRITE_PROTOCOL_DATA");
  return v != nullptr && std::string(v) == "1";
}

Pose3d pose(double yaw_rad, const Eigen::Vector3d& t) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = t;
  return T;
}

ModuleTimingsMs timings() {
  ModuleTimingsMs t;
  t.voxel = 0.5f, t.ground = 1.25f, t.segment = 2.5f, t.describe = 3.75f, t.retrieve = 0.125f;
  t.classify = 4.0f, t.verify = 0.25f, t.refine = 5.5f, t.total = 17.875f, t.server_total = 18.5f;
  return t;
}

// The localized reply of localize_reply_localized.bin, with another request id.
LocalizeReply localized_reply(uint64_t request_id) {
  LocalizeReply r;
  r.request_id = request_id;
  r.status = LocalizeStatus::kLocalized;
  r.T_map_local = pose(-M_PI / 2, Eigen::Vector3d(162.5, 84.25, 3.5));
  r.inliers = 3;
  r.confidence = 0.875f;
  r.support = 12;
  r.matched_segment_ids = {4, 17, 1099511627776ull};
  r.timings = timings();
  return r;
}

// Checks (or, when writing, first writes) one file: it equals encode(expected), decodes, and the
// decoded message re-encodes to the same bytes; `fields` checks values the bytes alone don't show.
template <typename M>
void check_file(const std::string& name, const M& expected, const std::function<void(const M&)>& fields = {}) {
  const std::vector<uint8_t> want = encode(expected);
  {  // The expected message must be a fixed point of the codec, or its file could never be stable.
    M back;
    ASSERT_EQ(decode_frame(want, Limits{}, back), DecodeStatus::kOk) << name;
    ASSERT_EQ(encode(back), want) << name << ": the expected message does not survive a round trip";
  }
  const std::string path = kDir + name;
  if (writing()) {
    std::filesystem::create_directories(kDir);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(want.data()), static_cast<std::streamsize>(want.size()));
    ASSERT_TRUE(out.good()) << "cannot write " << path;
  }
  std::ifstream in(path, std::ios::binary);
  ASSERT_TRUE(in.good()) << path << " is missing; write it with SEGMATCH_WRITE_PROTOCOL_DATA=1";
  const std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  EXPECT_EQ(bytes, want) << name << ": the encoder no longer writes the stored bytes for the listed values";
  M decoded;
  ASSERT_EQ(decode_frame(bytes, Limits{}, decoded), DecodeStatus::kOk) << name;
  EXPECT_EQ(encode(decoded), bytes) << name << ": decoded and re-encoded, the bytes differ";
  if (fields) fields(decoded);
}

const std::set<std::string> kFiles = {"hello.bin",
                                      "hello_ok.bin",
                                      "ping.bin",
                                      "pong.bin",
                                      "info.bin",
                                      "info_reply.bin",
                                      "localize_global.bin",
                                      "localize_prior_voxelized.bin",
                                      "localize_segments.bin",
                                      "localize_reply_localized.bin",
                                      "localize_reply_not_localized.bin",
                                      "localize_reply_outside_prior.bin",
                                      "localize_refusal_code.bin",
                                      "localize_reply_refused.bin",
                                      "localize_detail.bin",
                                      "localize_reply_detail.bin",
                                      "localize_reply_estimate.bin",
                                      "localize_newest.bin",
                                      "localize_segments_newest.bin",
                                      "localize_reply_off_map.bin",
                                      "error.bin",
                                      "localize_segments_track.bin",
                                      "localize_reply_tracking_lost.bin",
                                      "localize_reply_surfaces.bin",
                                      "localize_track.bin",
                                      "localize_reply_places.bin"};

}  // namespace

TEST(ProtocolData, Hello) {
  check_file<HelloRequest>("hello.bin", {"segmatch-token-1"},
                           [](const HelloRequest& m) { EXPECT_EQ(m.token, "segmatch-token-1"); });
}

TEST(ProtocolData, HelloOk) { check_file<HelloOkReply>("hello_ok.bin", {}); }

constexpr uint64_t kNonce = 0x0123456789ABCDEFull;

TEST(ProtocolData, PingAndPong) {
  check_file<PingRequest>("ping.bin", {kNonce}, [](const PingRequest& m) { EXPECT_EQ(m.nonce, kNonce); });
  check_file<PongReply>("pong.bin", {kNonce}, [](const PongReply& m) { EXPECT_EQ(m.nonce, kNonce); });
}

TEST(ProtocolData, InfoAndInfoReply) {
  check_file<InfoRequest>("info.bin", {});
  InfoReply r;
  r.map_name = "tiny-3";
  r.segment_count = 175;
  r.extent_min = Eigen::Vector3d(-51.625, 90.5, -2.5);
  r.extent_max = Eigen::Vector3d(87.625, 165.125, 2.625);
  r.parameters_json = kParametersJson;
  check_file<InfoReply>("info_reply.bin", r, [](const InfoReply& m) {
    EXPECT_EQ(m.protocol_version, 1);
    EXPECT_EQ(m.map_name, "tiny-3");
    EXPECT_EQ(m.extent_max.y(), 165.125);
  });
}

TEST(ProtocolData, LocalizeGlobal) {
  LocalizeRequest r;
  r.request_id = 7;
  r.sensor_position_local = Eigen::Vector3d(0.25, -1.5, 1.75);
  r.sensor_orientation_local = Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5);  // w x y z: all four differ in sign or place
  r.point_stride = 3;
  r.points = {{1.f, 2.f, 3.f, 0.f}, {-4.5f, 0.25f, 10.f, 0.f}, {12.125f, -7.f, 0.5f, 0.f}, {0.1f, 0.2f, 0.3f, 0.f}};
  check_file<LocalizeRequest>("localize_global.bin", r, [](const LocalizeRequest& m) {
    EXPECT_EQ(m.flags, 0u);
    EXPECT_EQ(m.sensor_orientation_local.w(), 0.5);
    EXPECT_EQ(m.sensor_orientation_local.y(), -0.5);
    ASSERT_EQ(m.points.size(), 4u);
    EXPECT_EQ(m.points[3].x, 0.1f);
  });
  // Revision 5: the same, asking for the reply's refusal code (bit 3).
  r.request_id = 12;
  r.flags = kFlagRefusalCode;
  check_file<LocalizeRequest>("localize_refusal_code.bin", r, [](const LocalizeRequest& m) { EXPECT_EQ(m.flags, 8u); });
}

TEST(ProtocolData, LocalizeWithPriorVoxelizedAndHeading) {
  LocalizeRequest r;
  r.request_id = 0x0102030405060708ull;
  r.flags = kFlagHasPrior | kFlagVoxelized | kFlagPriorHeading;
  r.sensor_position_local = Eigen::Vector3d(1.5, -2.25, 1.73);
  r.sensor_orientation_local = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 6, Eigen::Vector3d::UnitZ()));
  r.T_map_local_prior = pose(M_PI / 2, Eigen::Vector3d(100.0, 50.0, -3.0));
  r.prior_radius_m = 20.0;
  r.prior_heading_tolerance_deg = 15.0;
  r.point_stride = 4;
  r.points = {{1.f, 2.f, 3.f, 0.5f}, {-4.f, 5.25f, 0.f, 1.f}, {7.f, -8.f, 9.5f, 0.f}};
  check_file<LocalizeRequest>("localize_prior_voxelized.bin", r, [](const LocalizeRequest& m) {
    EXPECT_EQ(m.prior_radius_m, 20.0);
    EXPECT_EQ(m.prior_heading_tolerance_deg, 15.0);
    EXPECT_NEAR(m.T_map_local_prior(0, 1), -1.0, 1e-15) << "yaw +90 deg: x_map = -y_local + 100";
    EXPECT_EQ(m.points[1].intensity, 1.f);
  });
}

// A LOCALIZE with a prior at (100, 200, 0), three points and two newest points (bit 5).
LocalizeRequest newest_request(uint64_t id, uint32_t flags, double radius_m) {
  LocalizeRequest r;
  r.request_id = id;
  r.flags = flags;
  r.sensor_position_local = Eigen::Vector3d(1.0, 2.0, 0.5);
  r.T_map_local_prior = pose(0.0, Eigen::Vector3d(100.0, 200.0, 0.0));
  r.prior_radius_m = radius_m;
  r.point_stride = 3;
  r.points = {{1.f, 0.f, 0.f, 0.f}, {0.f, 1.f, 0.f, 0.f}, {0.f, 0.f, 1.f, 0.f}};
  r.newest_points = {{1.5f, -2.f, 0.25f, 0.f}, {3.f, 4.f, -0.5f, 0.f}};
  return r;
}

// Revision 8: the vehicle's newest scans after the points (bit 5).
TEST(ProtocolData, LocalizeNewest) {
  const LocalizeRequest r = newest_request(11, kFlagHasPrior | kFlagNewestScans, 5.0);
  check_file<LocalizeRequest>("localize_newest.bin", r, [](const LocalizeRequest& m) {
    EXPECT_EQ(m.flags, 33u);
    ASSERT_EQ(m.points.size(), 3u);
    ASSERT_EQ(m.newest_points.size(), 2u);
    EXPECT_EQ(m.newest_points[1].y, 4.f);
    EXPECT_EQ(m.newest_points[1].z, -0.5f);
  });
}

TEST(ProtocolData, LocalizeSegments) {
  LocalizeSegmentsRequest r;
  r.request_id = 11;
  r.flags = kSegmentsFlagHasPrior | kSegmentsFlagEsf;
  r.sensor_position_local = Eigen::Vector3d(10.0, 20.0, 1.75);
  r.T_map_local_prior = pose(M_PI, Eigen::Vector3d(-5.0, 2.5, 0.0));
  r.prior_radius_m = 12.5;
  r.prior_heading_tolerance_deg = 7.5;
  r.parameters_digest = segments_digest(kParametersJson);
  for (int k = 0; k < 2; ++k) {
    Segment s;
    const float c = 4.f * static_cast<float>(k + 1);
    s.points = {{c, 1.f, 0.5f, 0.f}, {c + 0.75f, 1.5f, 0.25f, 0.f}, {c - 0.5f, 0.25f, 2.f, 0.f}};
    for (const Point& p : s.points) s.centroid += p.xyz() / 3.f;
    for (int i = 0; i < kEigenFeatureCount; ++i) s.eigen[i] = 0.125f * static_cast<float>(i + k + 1);
    for (int i = 0; i < kEsfBins; ++i) s.esf[i] = (i % 64 == k) ? 0.0625f : 0.f;
    r.segments.push_back(s);
  }
  check_file<LocalizeSegmentsRequest>("localize_segments.bin", r, [](const LocalizeSegmentsRequest& m) {
    EXPECT_EQ(m.parameters_digest, segments_digest(kParametersJson));
    ASSERT_EQ(m.segments.size(), 2u);
    EXPECT_NEAR(m.segments[1].points[1].x, 8.75f, 1e-3f);
    EXPECT_EQ(m.segments[0].esf[64], 0.0625f);
  });
}

// Revision 10: LOCALIZE_SEGMENTS bit 4, the newest scans after the segments.
TEST(ProtocolData, LocalizeSegmentsNewest) {
  LocalizeSegmentsRequest r;
  r.request_id = 15;
  r.flags = kSegmentsFlagHasPrior | kSegmentsFlagRefusalCode | kSegmentsFlagNewestScans;
  r.sensor_position_local = Eigen::Vector3d(1.0, 2.0, 0.5);
  r.T_map_local_prior = pose(0.0, Eigen::Vector3d(100.0, 200.0, 0.0));
  r.prior_radius_m = 5.0;
  r.parameters_digest = segments_digest(kParametersJson);
  Segment s;
  s.points = {{4.f, 1.f, 0.5f, 0.f}, {4.75f, 1.5f, 0.25f, 0.f}};
  for (const Point& p : s.points) s.centroid += p.xyz() / 2.f;
  for (int i = 0; i < kEigenFeatureCount; ++i) s.eigen[i] = 0.25f * static_cast<float>(i + 1);
  r.segments.push_back(s);
  r.newest_points = {{1.5f, -2.f, 0.25f, 0.f}, {3.f, 4.f, -0.5f, 0.f}, {0.125f, 0.f, 8.f, 0.f}};
  check_file<LocalizeSegmentsRequest>("localize_segments_newest.bin", r, [](const LocalizeSegmentsRequest& m) {
    EXPECT_EQ(m.flags, 21u);
    ASSERT_EQ(m.segments.size(), 1u);
    ASSERT_EQ(m.newest_points.size(), 3u);
    EXPECT_EQ(m.newest_points[2].z, 8.f);
    EXPECT_EQ(m.newest_points[0].x, 1.5f);
  });
}

TEST(ProtocolData, LocalizeReplies) {
  const LocalizeReply ok = localized_reply(7);
  check_file<LocalizeReply>("localize_reply_localized.bin", ok, [](const LocalizeReply& m) {
    EXPECT_EQ(m.status, LocalizeStatus::kLocalized);
    EXPECT_NEAR(m.T_map_local(1, 0), -1.0, 1e-15) << "yaw -90 deg";
    EXPECT_EQ(m.timings.server_total, 18.5f);
  });

  LocalizeReply no;
  no.request_id = 8;
  no.status = LocalizeStatus::kNotLocalized;
  no.reason = "too few segments: 2 < 4";
  no.timings = timings();
  check_file<LocalizeReply>("localize_reply_not_localized.bin", no, [](const LocalizeReply& m) {
    EXPECT_EQ(m.reason, "too few segments: 2 < 4");
    EXPECT_TRUE(m.T_map_local.isApprox(Pose3d::Identity()));
  });

  LocalizeReply outside = ok;
  outside.request_id = 9;
  outside.status = LocalizeStatus::kOutsidePrior;
  outside.reason = "pose 152.3 m from the prior (radius 0 m)";
  outside.matched_segment_ids = {1, 2, 3};
  check_file<LocalizeReply>("localize_reply_outside_prior.bin", outside,
                            [](const LocalizeReply& m) { EXPECT_EQ(m.status, LocalizeStatus::kOutsidePrior); });

  LocalizeReply refused = no;  // revision 5: the answer to localize_refusal_code.bin
  refused.request_id = 12;
  refused.refusal = RefusalCode::kAmbiguous;
  refused.reason = "ambiguous: two distinct poses are supported by 16 and 15 query segments";
  check_file<LocalizeReply>("localize_reply_refused.bin", refused,
                            [](const LocalizeReply& m) { EXPECT_EQ(static_cast<int>(m.refusal), 6); });
}

// Revision 6: a request that asks for the detail block, and a localized reply carrying one.
TEST(ProtocolData, LocalizeDetail) {
  LocalizeRequest asks;
  asks.request_id = 13;
  asks.flags = kFlagDetail;
  asks.sensor_position_local = Eigen::Vector3d(0.25, -1.5, 1.75);
  asks.sensor_orientation_local = Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5);
  asks.point_stride = 3;
  asks.points = {{1, 2, 3, 0}, {-4.5f, 0.25f, 10, 0}, {12.125f, -7, 0.5f, 0}, {0.1f, 0.2f, 0.3f, 0}};
  check_file<LocalizeRequest>("localize_detail.bin", asks, [](const LocalizeRequest& m) { EXPECT_EQ(m.flags, 16u); });

  LocalizeReply with = localized_reply(13);
  with.detail = ReplyDetail{0.375f, 0.25f, 1234, {}};
  check_file<LocalizeReply>("localize_reply_detail.bin", with, [](const LocalizeReply& m) {
    ASSERT_TRUE(m.detail.has_value());
    EXPECT_FALSE(m.detail->estimate.has_value()) << "a revision-6 block (D = 12) has no method or covariance";
    EXPECT_EQ(m.detail->window_warp_m, 0.375f);
    EXPECT_EQ(m.detail->window_warp_deg, 0.25f);
    EXPECT_EQ(m.detail->window_points, 1234u);
  });
}

// A revision-7 detail block: the window fields, the method and covariance entries (k + first) / scale.
ReplyDetail detail_with_estimate(float warp_m, float warp_deg, uint32_t points, ReplyMethod method, int first,
                                 float scale) {
  ReplyDetail d{warp_m, warp_deg, points, {}};
  ReplyDetail::Estimate e;
  e.method = static_cast<uint8_t>(method);
  for (size_t k = 0; k < e.covariance_upper.size(); ++k) e.covariance_upper[k] = static_cast<float>(k + first) / scale;
  d.estimate = e;
  return d;
}

// Revision 7: the detail block with the answer's method and covariance (D = 100).
TEST(ProtocolData, LocalizeEstimate) {
  LocalizeReply with = localized_reply(14);
  with.detail = detail_with_estimate(0.125f, 0.0625f, 2000, ReplyMethod::kRegistration, 1, 4096.0f);
  check_file<LocalizeReply>("localize_reply_estimate.bin", with, [](const LocalizeReply& m) {
    ASSERT_TRUE(m.detail.has_value());
    ASSERT_TRUE(m.detail->estimate.has_value());
    EXPECT_EQ(m.detail->estimate->method, 1u);
    const Eigen::Matrix<double, 6, 6> c = covariance_matrix(m.detail->estimate->covariance_upper);
    EXPECT_EQ(c(0, 5), 6.0 / 4096.0);
    EXPECT_EQ(c(5, 0), 6.0 / 4096.0);
    EXPECT_EQ(c(5, 5), 21.0 / 4096.0);
    EXPECT_EQ(covariance_upper(c), m.detail->estimate->covariance_upper);
  });
}

// Revision 9: refusal code 9, OFF_MAP, answering a request that carried its newest scans.
TEST(ProtocolData, LocalizeReplyOffMap) {
  LocalizeReply off;
  off.request_id = 11;  // the answer to localize_newest.bin
  off.status = LocalizeStatus::kNotLocalized;
  off.refusal = RefusalCode::kOffMap;
  off.reason =
      "the vehicle's newest scans do not lie on the map's surfaces at the answer (fitness 0.53, at least 0.55)";
  off.timings = timings();
  check_file<LocalizeReply>("localize_reply_off_map.bin", off, [](const LocalizeReply& m) {
    EXPECT_EQ(static_cast<int>(m.refusal), 9);
    EXPECT_STREQ(to_string(m.refusal), "OFF_MAP");
    EXPECT_STREQ(to_string(RefusalCode::kNewestScansDisagree), "NEWEST_SCANS_DISAGREE");
    EXPECT_STREQ(to_string(static_cast<RefusalCode>(12)), "UNKNOWN") << "a later revision's code";
    EXPECT_EQ(m.status, LocalizeStatus::kNotLocalized);
  });
}

// Revision 11: LOCALIZE bit 6, tracking first (the cloud is there for the rest).
TEST(ProtocolData, LocalizeTrack) {
  const LocalizeRequest r = newest_request(17, kFlagHasPrior | kFlagNewestScans | kFlagTrack, 3.0);
  check_file<LocalizeRequest>("localize_track.bin", r, [](const LocalizeRequest& m) { EXPECT_EQ(m.flags, 97u); });
  for (uint32_t drop : {kFlagHasPrior, kFlagNewestScans}) {
    LocalizeRequest bad = r;
    bad.flags &= ~drop;
    if (drop == kFlagNewestScans) bad.newest_points.clear();
    LocalizeRequest out;
    EXPECT_EQ(decode_frame(encode(bad), Limits{}, out), DecodeStatus::kBadField) << drop;
  }
}

// Revision 11: LOCALIZE_SEGMENTS bit 5, tracking on the surface layer: segments without points,
// the newest scans; answered TRACKING_LOST (code 11), or localized by method 2.
TEST(ProtocolData, LocalizeSegmentsTrack) {
  LocalizeSegmentsRequest r;
  r.request_id = 16;
  r.flags = kSegmentsFlagHasPrior | kSegmentsFlagRefusalCode | kSegmentsFlagDetail | kSegmentsFlagNewestScans |
            kSegmentsFlagTrack;
  r.sensor_position_local = Eigen::Vector3d(1.0, 2.0, 0.5);
  r.T_map_local_prior = pose(0.5, Eigen::Vector3d(100.0, 200.0, 0.0));
  r.prior_radius_m = 3.0;
  r.prior_heading_tolerance_deg = 5.0;
  r.parameters_digest = segments_digest(kParametersJson);
  for (int k = 0; k < 2; ++k) {
    Segment s;
    s.centroid = Eigen::Vector3f(4.f * static_cast<float>(k + 1), 1.f, 0.5f);
    for (int i = 0; i < kEigenFeatureCount; ++i) s.eigen[i] = 0.25f * static_cast<float>(i + k + 1);
    r.segments.push_back(s);
  }
  r.newest_points = {{1.5f, -2.f, 0.25f, 0.f}, {3.f, 4.f, -0.5f, 0.f}};
  check_file<LocalizeSegmentsRequest>("localize_segments_track.bin", r, [](const LocalizeSegmentsRequest& m) {
    EXPECT_EQ(m.flags, 61u);
    ASSERT_EQ(m.segments.size(), 2u);
    EXPECT_TRUE(m.segments[1].points.empty());
    EXPECT_EQ(m.segments[1].centroid.x(), 8.f);
    ASSERT_EQ(m.newest_points.size(), 2u);
  });
  // Bit 5 without the prior or without the newest scans is malformed.
  for (uint32_t drop : {kSegmentsFlagHasPrior, kSegmentsFlagNewestScans}) {
    LocalizeSegmentsRequest bad = r;
    bad.flags &= ~drop;
    if (drop == kSegmentsFlagNewestScans) bad.newest_points.clear();
    LocalizeSegmentsRequest out;
    EXPECT_EQ(decode_frame(encode(bad), Limits{}, out), DecodeStatus::kBadField) << drop;
  }

  LocalizeReply lost;
  lost.request_id = 16;
  lost.status = LocalizeStatus::kNotLocalized;
  lost.refusal = RefusalCode::kTrackingLost;
  lost.reason = "tracking on the surface layer: registration fitness 0.61 below 0.75";
  lost.timings = timings();
  check_file<LocalizeReply>("localize_reply_tracking_lost.bin", lost, [](const LocalizeReply& m) {
    EXPECT_EQ(static_cast<int>(m.refusal), 11);
    EXPECT_STREQ(to_string(m.refusal), "TRACKING_LOST");
  });
  LocalizeReply tracked = localized_reply(16);
  tracked.detail = detail_with_estimate(0.f, 0.f, 3100, ReplyMethod::kSurfaces, 2, 8192.0f);
  check_file<LocalizeReply>("localize_reply_surfaces.bin", tracked, [](const LocalizeReply& m) {
    ASSERT_TRUE(m.detail && m.detail->estimate);
    EXPECT_EQ(m.detail->estimate->method, 2u);
    EXPECT_STREQ(to_string(static_cast<ReplyMethod>(m.detail->estimate->method)), "surfaces");
  });
  // Revision 12: method 3, a cold start answered by place recognition; the block is a revision-7
  // block byte for byte but for the value, which revision-7 decoders read as a method they cannot name.
  LocalizeReply cold = localized_reply(17);
  cold.detail = detail_with_estimate(0.f, 0.f, 5200, ReplyMethod::kPlaces, 3, 8192.0f);
  check_file<LocalizeReply>("localize_reply_places.bin", cold, [](const LocalizeReply& m) {
    ASSERT_TRUE(m.detail && m.detail->estimate);
    EXPECT_EQ(m.detail->estimate->method, 3u);
    EXPECT_STREQ(to_string(static_cast<ReplyMethod>(m.detail->estimate->method)), "places");
  });
}

TEST(ProtocolData, Error) {
  check_file<ErrorReply>("error.bin", {ErrorCode::kNonFinite, "NaN or Inf value"}, [](const ErrorReply& m) {
    EXPECT_EQ(static_cast<int>(m.code), 7);
    EXPECT_EQ(m.message, "NaN or Inf value");
  });
}

// Last, so that with SEGMATCH_WRITE_PROTOCOL_DATA=1 it sees the files just written.
TEST(ProtocolData, EveryStoredFrameIsCheckedHere) {
  std::set<std::string> stored;
  for (const auto& entry : std::filesystem::directory_iterator(kDir))
    if (entry.path().extension() == ".bin") stored.insert(entry.path().filename().string());
  EXPECT_EQ(stored, kFiles) << "a frame in " << kDir << " that no test reads, or one missing";
}
