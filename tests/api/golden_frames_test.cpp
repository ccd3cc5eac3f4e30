// Frames stored from revision 1 of the protocol (tests/api/golden/, written by the codec before
// revision 2 existed) are decoded by today's codec to the same fields and re-encoded to the same
// bytes: a v1 client keeps working (docs/protocol.md 8, rule 5). One exception: a pose is held
// as a matrix, so the prior's quaternion comes back within 1e-15, not always bit for bit.
#include "segmatch/api/protocol.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

using namespace segmatch;
using namespace segmatch::api;

namespace {

std::vector<uint8_t> golden(const std::string& name) {
  std::ifstream in(std::string(SEGMATCH_SOURCE_DIR) + "/tests/api/golden/" + name, std::ios::binary);
  EXPECT_TRUE(in.good()) << name;
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

}  // namespace

TEST(GoldenFrames, Revision1LocalizeWithPriorDecodesAndReencodesByteForByte) {
  const std::vector<uint8_t> bytes = golden("localize_v1_prior_voxelized.bin");
  ASSERT_EQ(bytes.size(), 200u);
  LocalizeRequest r;
  ASSERT_EQ(decode_frame(bytes, Limits{}, r), DecodeStatus::kOk);
  EXPECT_EQ(r.request_id, 0x0102030405060708ull);
  EXPECT_EQ(r.flags, kFlagHasPrior | kFlagVoxelized);
  EXPECT_EQ(r.sensor_position_local, Eigen::Vector3d(1.5, -2.25, 1.73));
  EXPECT_EQ(r.T_map_local_prior.translation(), Eigen::Vector3d(100.0, 50.0, -3.0));
  EXPECT_NEAR(Eigen::AngleAxisd(r.T_map_local_prior.linear()).angle(), 0.25, 1e-12);
  EXPECT_EQ(r.prior_radius_m, 20.0);
  EXPECT_EQ(r.prior_heading_tolerance_deg, 10.0) << "revision 1 sends none: the server's default";
  ASSERT_EQ(r.points.size(), 3u);
  EXPECT_EQ(r.points[1].y, 5.25f);
  const std::vector<uint8_t> again = encode(r);
  ASSERT_EQ(again.size(), bytes.size());
  constexpr size_t kPriorQuaternion = kHeaderBytes + 68;  // 4 x f64 (docs/protocol.md 5.4)
  for (size_t i = 0; i < bytes.size(); ++i)
    if (i < kPriorQuaternion || i >= kPriorQuaternion + 32) {
      EXPECT_EQ(again[i], bytes[i]) << "byte " << i;
    }
  for (size_t k = 0; k < 4; ++k) {
    double a, b;
    std::memcpy(&a, &bytes[kPriorQuaternion + 8 * k], 8);
    std::memcpy(&b, &again[kPriorQuaternion + 8 * k], 8);
    EXPECT_NEAR(a, b, 1e-15);
  }
}

TEST(GoldenFrames, Revision1GlobalLocalizeDecodesAndReencodesByteForByte) {
  const std::vector<uint8_t> bytes = golden("localize_v1_global.bin");
  LocalizeRequest r;
  ASSERT_EQ(decode_frame(bytes, Limits{}, r), DecodeStatus::kOk);
  EXPECT_EQ(r.request_id, 7u);
  EXPECT_EQ(r.flags, 0u);
  EXPECT_EQ(r.point_stride, 3u);
  ASSERT_EQ(r.points.size(), 1u);
  EXPECT_EQ(encode(r), bytes);
}

// Revision 4's REQUEST_TIMEOUT, as a server sends it: an ERROR frame like every other (rule 6),
// so revision 1's decoder reads it as a failed request with code 16 and its message.
TEST(GoldenFrames, Revision4RequestTimeoutErrorDecodesAndReencodesByteForByte) {
  const std::vector<uint8_t> bytes = golden("error_request_timeout_v4.bin");
  ErrorReply e;
  ASSERT_EQ(decode_frame(bytes, Limits{}, e), DecodeStatus::kOk);
  EXPECT_EQ(e.code, ErrorCode::kRequestTimeout);
  EXPECT_EQ(static_cast<int>(e.code), 16);
  EXPECT_EQ(e.message, "request timed out: the query's deadline passed during segmentation");
  EXPECT_EQ(encode(e), bytes);
}
