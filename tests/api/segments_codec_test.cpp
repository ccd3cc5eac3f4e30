// LOCALIZE_SEGMENTS (docs/protocol.md 5.5): what survives the quantisation, that a decoded
// request re-encodes to the same bytes, the stored revision-3 frame, the digest, and every
// malformed payload refused with its status.
#include "segmatch/api/protocol.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>

using namespace segmatch;
using namespace segmatch::api;

namespace {

const Limits kLimits;
constexpr size_t kOffFlags = kHeaderBytes + 8;
constexpr size_t kOffRadius = kHeaderBytes + 124;
constexpr size_t kOffCount = kHeaderBytes + 148;
constexpr size_t kOffPoints = kHeaderBytes + 152;
constexpr size_t kOffFirstSegment = kHeaderBytes + 156;

// A segment of n points scattered up to `extent_m` around `centre`, with made-up descriptors.
Segment make_segment(std::mt19937& rng, const Eigen::Vector3f& centre, float extent_m, size_t n, bool esf) {
  std::uniform_real_distribution<float> u(-extent_m, extent_m);
  Segment s;
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  for (size_t i = 0; i < n; ++i) {
    const Point p{centre.x() + u(rng), centre.y() + u(rng), centre.z() + u(rng), 0.f};
    s.points.push_back(p);
    sum += p.xyz();
  }
  s.centroid = sum / static_cast<float>(n);
  for (int k = 0; k < kEigenFeatureCount; ++k) s.eigen[k] = 0.1f * static_cast<float>(k + 1) / 3.f;
  s.has_eigen = true;
  if (esf) {
    std::uniform_real_distribution<float> bin(0.f, 0.01f);
    float total = 0.f;
    for (float& v : s.esf) total += (v = (rng() % 3 == 0) ? 0.f : bin(rng));
    for (float& v : s.esf) v /= total;
    s.has_esf = true;
  }
  return s;
}

LocalizeSegmentsRequest some_request(bool esf, size_t segments = 5) {
  std::mt19937 rng(7);
  LocalizeSegmentsRequest r;
  r.request_id = 42;
  r.flags = kSegmentsFlagHasPrior | (esf ? kSegmentsFlagEsf : 0u);
  r.sensor_position_local = Eigen::Vector3d(120.5, -33.25, 1.73);
  r.sensor_orientation_local = Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()));
  r.T_map_local_prior.translation() = Eigen::Vector3d(5.0, 6.0, 0.5);
  r.prior_radius_m = 15.0;
  r.prior_heading_tolerance_deg = 7.5;
  r.parameters_digest = 0x1122334455667788ull;
  for (size_t i = 0; i < segments; ++i)
    r.segments.push_back(
        make_segment(rng, Eigen::Vector3f(100.f + 7.f * i, -20.f, 1.f), 0.5f + 2.f * i, 50 + 30 * i, esf));
  return r;
}

void put_u32(std::vector<uint8_t>& f, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) f[at + i] = static_cast<uint8_t>(v >> (8 * i));
}
void put_f32(std::vector<uint8_t>& f, size_t at, float v) {
  uint32_t b;
  std::memcpy(&b, &v, 4);
  put_u32(f, at, b);
}

DecodeStatus decode_request(const std::vector<uint8_t>& frame) {
  LocalizeSegmentsRequest r;
  return decode_frame(frame, kLimits, r);
}

}  // namespace

TEST(SegmentsCodec, RoundTripKeepsFeaturesExactlyAndPointsWithinHalfAStep) {
  for (bool esf : {false, true}) {
    const LocalizeSegmentsRequest in = some_request(esf);
    LocalizeSegmentsRequest out;
    ASSERT_EQ(decode_frame(encode(in), kLimits, out), DecodeStatus::kOk);
    EXPECT_EQ(out.request_id, in.request_id);
    EXPECT_EQ(out.flags, in.flags);
    EXPECT_EQ(out.sensor_position_local, in.sensor_position_local);
    EXPECT_NEAR(out.T_map_local_prior.translation().x(), 5.0, 0.0);
    EXPECT_EQ(out.prior_radius_m, 15.0);
    EXPECT_EQ(out.prior_heading_tolerance_deg, 7.5);
    EXPECT_EQ(out.parameters_digest, in.parameters_digest);
    ASSERT_EQ(out.segments.size(), in.segments.size());
    for (size_t i = 0; i < in.segments.size(); ++i) {
      const Segment &a = in.segments[i], &b = out.segments[i];
      EXPECT_EQ(b.id, i);
      EXPECT_EQ(b.centroid, a.centroid);
      EXPECT_EQ(b.eigen, a.eigen);
      EXPECT_TRUE(b.has_eigen);
      EXPECT_EQ(b.has_esf, esf);
      ASSERT_EQ(b.points.size(), a.points.size());
      // The step is the power of two at or above reach / 32767: half of it is < reach / 32767.
      float reach = 0.f;
      for (const Point& p : a.points) reach = std::max(reach, (p.xyz() - a.centroid).cwiseAbs().maxCoeff());
      for (size_t k = 0; k < a.points.size(); ++k)
        EXPECT_LE((b.points[k].xyz() - a.points[k].xyz()).cwiseAbs().maxCoeff(), reach / 32767.f + 8e-6f);
      if (!esf) continue;
      const float largest = *std::max_element(a.esf.begin(), a.esf.end());
      for (int k = 0; k < kEsfBins; ++k) EXPECT_LE(std::abs(b.esf[k] - a.esf[k]), largest / 65535.f * 1.001f) << k;
    }
  }
}

TEST(SegmentsCodec, LargeSegmentsUseACoarserStepAndStillRoundTrip) {
  std::mt19937 rng(3);
  LocalizeSegmentsRequest in;
  in.segments.push_back(make_segment(rng, Eigen::Vector3f(0.f, 0.f, 0.f), 100.f, 200, false));  // a building
  LocalizeSegmentsRequest out;
  ASSERT_EQ(decode_frame(encode(in), kLimits, out), DecodeStatus::kOk);
  // ~100 m from the centroid needs 2^-8 m steps (i16 range 128 m): 2 mm at worst.
  for (size_t k = 0; k < 200; ++k)
    EXPECT_LE((out.segments[0].points[k].xyz() - in.segments[0].points[k].xyz()).cwiseAbs().maxCoeff(),
              0.5f / 256.f + 1e-4f);
}

TEST(SegmentsCodec, DecodedRequestReencodesToTheSameBytes) {
  for (bool esf : {false, true}) {
    const std::vector<uint8_t> first = encode(some_request(esf));
    LocalizeSegmentsRequest decoded;
    ASSERT_EQ(decode_frame(first, kLimits, decoded), DecodeStatus::kOk);
    EXPECT_EQ(encode(decoded), first);
  }
}

TEST(SegmentsCodec, LayoutIsTheDocumentedOne) {
  const LocalizeSegmentsRequest r = some_request(true, 2);
  const std::vector<uint8_t> f = encode(r);
  size_t points = 0;
  for (const Segment& s : r.segments) points += s.points.size();
  EXPECT_EQ(f.size(), kHeaderBytes + 156 + 2 * (45 + 1281) + 6 * points);
  float cx;
  std::memcpy(&cx, &f[kOffFirstSegment], 4);
  EXPECT_EQ(cx, r.segments[0].centroid.x());
  // The smallest power of two at or above reach / 32767 m, not below 2^-16 m.
  float reach = 0.f;
  for (const Point& p : r.segments[0].points)
    reach = std::max(reach, (p.xyz() - r.segments[0].centroid).cwiseAbs().maxCoeff());
  const int expected = std::max(-16, static_cast<int>(std::ceil(std::log2(reach / 32767.0))));
  EXPECT_EQ(static_cast<int8_t>(f[kOffFirstSegment + 44]), expected) << "reach " << reach;
}

TEST(SegmentsCodec, StoredRevision3FrameDecodesAndReencodesByteForByte) {
  const std::string path = std::string(SEGMATCH_SOURCE_DIR) + "/tests/api/golden/localize_segments_v3.bin";
  std::ifstream in(path, std::ios::binary);
  ASSERT_TRUE(in.good()) << path;
  const std::vector<uint8_t> bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  LocalizeSegmentsRequest r;
  ASSERT_EQ(decode_frame(bytes, kLimits, r), DecodeStatus::kOk);
  EXPECT_EQ(r.request_id, 42u);
  EXPECT_EQ(r.flags, kSegmentsFlagHasPrior | kSegmentsFlagEsf);
  EXPECT_EQ(r.parameters_digest, 0x1122334455667788ull);
  ASSERT_EQ(r.segments.size(), 2u);
  EXPECT_EQ(r.segments[1].points.size(), 80u);
  EXPECT_EQ(encode(r), bytes);
}

TEST(SegmentsCodec, DigestIsPinnedAndNamesTheJsonByteForByte) {
  // FNV-1a 64 of "segmatch-segments/", u32 1 (kSegmentCodeVersion), "{}", computed apart (in
  // Python): pinned, so a change of the digest (vehicles compute it too) cannot go unnoticed.
  EXPECT_EQ(segments_digest("{}"), 0x4e89336d6d35ef44ull) << std::hex << segments_digest("{}");
  EXPECT_NE(segments_digest("{\"a\":1}"), segments_digest("{\"a\":2}"));
  EXPECT_NE(segments_digest("{}"), segments_digest("{} "));
}

TEST(SegmentsCodec, RefusesCountsThatDisagreeWithTheLength) {
  const std::vector<uint8_t> good = encode(some_request(true));
  ASSERT_EQ(decode_request(good), DecodeStatus::kOk);
  std::vector<uint8_t> f = good;
  put_u32(f, kOffCount, 6);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  f = good;
  put_u32(f, kOffPoints, 0xFFFFFFFFu);  // no 32-bit overflow
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  f = good;
  put_u32(f, kOffCount, 0xFFFFFFFFu);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  // The first segment claims one point more than it has: the header's counts still match the
  // length, but the segments' counts no longer add up to them (nor tile the payload).
  f = good;
  put_u32(f, kOffFirstSegment + 40, 51);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  // Clearing the ESF flag changes the expected length.
  f = good;
  put_u32(f, kOffFlags, kSegmentsFlagHasPrior);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
}

TEST(SegmentsCodec, RefusesEveryTruncation) {
  const std::vector<uint8_t> full = encode(some_request(true, 2));
  for (size_t n = 0; n + kHeaderBytes < full.size(); n += (n < 400 ? 1 : 53)) {
    std::vector<uint8_t> cut(full.begin(), full.begin() + kHeaderBytes + n);
    put_u32(cut, 8, static_cast<uint32_t>(n));
    EXPECT_NE(decode_request(cut), DecodeStatus::kOk) << n;
  }
}

TEST(SegmentsCodec, RefusesNonFiniteValuesBadFlagsAndExponents) {
  const std::vector<uint8_t> good = encode(some_request(true));
  std::vector<uint8_t> f = good;
  put_f32(f, kOffFirstSegment + 4, std::numeric_limits<float>::quiet_NaN());  // centroid y
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = good;
  put_f32(f, kOffFirstSegment + 12 + 8, std::numeric_limits<float>::infinity());  // eigen[2]
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = good;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::memcpy(&f[kOffRadius], &nan, 8);
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  f = good;
  const double negative = -1.0;
  std::memcpy(&f[kOffRadius], &negative, 8);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  f = good;
  put_u32(f, kOffFlags, kSegmentsFlagHasPrior | kSegmentsFlagEsf | 32u);  // bit 5: not defined by revision 10
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  f = good;
  put_u32(f, kOffFlags, kSegmentsFlagHasPrior | kSegmentsFlagEsf | kSegmentsFlagNewestScans);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount) << "bit 4 promises newest scans the payload lacks";
  f = good;
  f[kOffFirstSegment + 44] = static_cast<uint8_t>(int8_t{11});  // point step 2^11 m
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  f[kOffFirstSegment + 44] = static_cast<uint8_t>(int8_t{-17});  // point step 2^-17 m
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  f = good;
  f[kOffFirstSegment + 45] = static_cast<uint8_t>(int8_t{3});  // ESF scale 8
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadField);
  EXPECT_EQ(error_code_for(DecodeStatus::kBadPointCount), ErrorCode::kBadPointCount);
}

// Revision 10: the newest scans after the segments round-trip exactly (f32), and every count
// that disagrees with the length, a truncation inside them or a non-finite one is refused.
TEST(SegmentsCodec, NewestScansFollowTheSegments) {
  LocalizeSegmentsRequest in = some_request(true, 2);
  in.flags |= kSegmentsFlagNewestScans;
  for (int i = 0; i < 40; ++i) in.newest_points.push_back({0.25f * i, -1.5f + i, 0.125f * (i % 7), 0.f});
  const std::vector<uint8_t> good = encode(in);
  EXPECT_EQ(good.size(), encode(some_request(true, 2)).size() + 4 + 12 * 40);
  LocalizeSegmentsRequest out;
  ASSERT_EQ(decode_frame(good, kLimits, out), DecodeStatus::kOk);
  ASSERT_EQ(out.newest_points.size(), 40u);
  for (size_t i = 0; i < 40; ++i) EXPECT_EQ(out.newest_points[i].xyz(), in.newest_points[i].xyz());
  ASSERT_EQ(out.segments.size(), 2u);
  EXPECT_EQ(encode(out), good);
  const size_t count_at = good.size() - 4 - 12 * 40;
  std::vector<uint8_t> f = good;
  put_u32(f, count_at, 41);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  f = good;
  put_u32(f, count_at, 0xFFFFFFFFu);  // no 32-bit overflow
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
  f = good;
  put_f32(f, good.size() - 4, std::numeric_limits<float>::quiet_NaN());
  EXPECT_EQ(decode_request(f), DecodeStatus::kNonFinite);
  for (size_t cut = 1; cut <= 12 * 40 + 4; cut += 7) {
    f.assign(good.begin(), good.end() - static_cast<std::ptrdiff_t>(cut));
    put_u32(f, 8, static_cast<uint32_t>(f.size() - kHeaderBytes));
    EXPECT_NE(decode_request(f), DecodeStatus::kOk) << cut;
  }
  f = good;  // the bit cleared: the trailing scans no longer belong to the payload
  put_u32(f, kOffFlags, in.flags & ~kSegmentsFlagNewestScans);
  EXPECT_EQ(decode_request(f), DecodeStatus::kBadPointCount);
}

TEST(SegmentsCodec, IsAKnownRequestType) {
  EXPECT_TRUE(is_known_type(0x0005));
  EXPECT_STREQ(to_string(MessageType::kLocalizeSegments), "LOCALIZE_SEGMENTS");
}
