// The segment map follows a corrected trajectory (core/map_correction.h): each segment moves
// with the keyframe it was seen from, and two views of one object that drift had kept apart
// are merged once moved, keeping the larger view.
#include "segmatch/core/mapping/map_correction.h"

#include <gtest/gtest.h>

#include "support/poses.h"

using namespace segmatch;

namespace {

Segment box_at(uint64_t id, const Eigen::Vector3f& c, int points) {
  Segment s;
  s.id = id;
  for (int i = 0; i < points; ++i) {
    Point p;
    p.x = c.x() + 0.01f * static_cast<float>(i % 10);
    p.y = c.y() + 0.01f * static_cast<float>(i / 10);
    p.z = c.z();
    s.points.push_back(p);
  }
  s.centroid = c;
  return s;
}

Pose3d shift(double x, double y) { return test::pose_at(x, y); }

}  // namespace

TEST(CorrectSegmentMap, MovesSegmentsWithTheirKeyframesAndMergesDuplicates) {
  // One object seen from keyframe 10 at (20, 0) and, after 3 m of drift, from keyframe 90 at
  // (23, 0) in the odometry frame; another object seen only from keyframe 90 at (40, 5).
  const Segments segments = {box_at(1, {20, 0, 1}, 50), box_at(2, {23, 0, 1}, 80), box_at(3, {40, 5, 1}, 30)};
  const std::vector<size_t> frames = {10, 90, 90};
  // The correction takes keyframe 90's coordinates 3 m back; keyframe 10 was right.
  const CorrectedMap m = correct_segment_map(
      segments, frames, [](size_t frame) { return frame == 90 ? shift(-3, 0) : Pose3d::Identity(); }, {});
  ASSERT_EQ(m.segments.size(), 2u);
  EXPECT_EQ(m.merged, 1u);
  // The object keeps its first id and the larger (80-point) view, now at (20, 0).
  EXPECT_EQ(m.segments[0].id, 1u);
  EXPECT_EQ(m.segments[0].points.size(), 80u);
  EXPECT_NEAR(m.segments[0].centroid.x(), 20.0f, 1e-4f);
  EXPECT_NEAR(m.segments[0].points.front().x, 20.0f, 1e-4f);
  // The other moved with its keyframe.
  EXPECT_NEAR(m.segments[1].centroid.x(), 37.0f, 1e-4f);
  EXPECT_NEAR(m.segments[1].centroid.y(), 5.0f, 1e-4f);
}

TEST(CorrectSegmentMap, WithoutACorrectionNothingMovesOrMerges) {
  const Segments segments = {box_at(1, {20, 0, 1}, 50), box_at(2, {23, 0, 1}, 80)};
  const CorrectedMap m = correct_segment_map(segments, {10, 90}, [](size_t) { return Pose3d::Identity(); }, {});
  ASSERT_EQ(m.segments.size(), 2u);
  EXPECT_EQ(m.merged, 0u);
  EXPECT_NEAR(m.segments[1].centroid.x(), 23.0f, 1e-6f);
}

TEST(CorrectSegmentMap, RefusesMismatchedKeyframes) {
  EXPECT_THROW(correct_segment_map({box_at(1, {0, 0, 0}, 5)}, {}, [](size_t) { return Pose3d::Identity(); }, {}),
               std::invalid_argument);
}
