// The two real recordings in ../shared/data/real (see its README): skipped when absent.
#include <segmatch/io/sequence.h>

#include <algorithm>
#include <filesystem>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

void check_scan(const Sequence& seq, size_t i) {
  SCOPED_TRACE(seq.scan_path(i));
  const CloudData scan = seq.scan(i);
  EXPECT_GE(scan.points.size(), 1000u);
  EXPECT_LE(scan.points.size(), 200000u);
  EXPECT_TRUE(scan.has_intensity);
  EXPECT_TRUE(scan.labels.empty());
  // Real returns: intensities vary and the points spread over metres, not a constant blob.
  const auto [lo, hi] = std::minmax_element(scan.points.begin(), scan.points.end(),
                                            [](const Point& a, const Point& b) { return a.intensity < b.intensity; });
  EXPECT_LT(lo->intensity, hi->intensity);
  float max_range = 0.0f;
  for (const Point& p : scan.points) max_range = std::max(max_range, p.xyz().norm());
  EXPECT_GT(max_range, 5.0f);
  EXPECT_LT(max_range, 500.0f);
}

// max_step: largest distance between consecutive keyframes (riverside02 has one 63.5 m gap
// at its last keyframe; hku-loop1 keyframes are at most 0.6 m apart).
void check_real_sequence(const std::string& name, size_t expected_scans, double max_step) {
  const std::string folder = std::string(SEGMATCH_SHARED_DATA_DIR) + "/real/" + name;
  if (!std::filesystem::exists(folder)) GTEST_SKIP() << "../shared/data/real not found: skipping real-data test";
  const Sequence seq = Sequence::open(folder);
  EXPECT_EQ(seq.layout(), SequenceLayout::kPcdKeyframes);
  ASSERT_EQ(seq.size(), expected_scans);
  ASSERT_EQ(seq.poses().size(), expected_scans);
  EXPECT_TRUE(seq.has_times());
  EXPECT_FALSE(seq.has_labels());
  EXPECT_LT((seq.poses()[0].translation()).norm(), 0.1);  // world = first keyframe
  for (size_t i = 0; i < seq.size(); ++i) {
    ASSERT_TRUE(seq.poses()[i].matrix().allFinite()) << i;
    if (i == 0) continue;
    EXPECT_LT((seq.poses()[i].translation() - seq.poses()[i - 1].translation()).norm(), max_step) << i;
    EXPECT_GT(seq.times()[i], seq.times()[i - 1]) << i;
  }
  check_scan(seq, 0);
  check_scan(seq, seq.size() - 1);
}

TEST(RealData, Riverside02) { check_real_sequence("riverside02", 281, 70.0); }

TEST(RealData, HkuLoop1) { check_real_sequence("hku-loop1", 314, 2.0); }

}  // namespace
}  // namespace io
}  // namespace segmatch
