// SegmentMap keeps one segment per object: a fuller view replaces the nearest one, and when the
// replacement's centroid lands within the duplicate distance of another segment, the one with
// more points is kept, with the grid index consistent afterwards.
#include "segmatch/core/mapping/segment_map.h"

#include <gtest/gtest.h>

#include <random>
#include <set>

using namespace segmatch;

namespace {

SegmentMapConfig resolving() {
  SegmentMapConfig c;
  c.resolve_moved_duplicates = true;
  return c;
}

Segment segment(float x, float y, size_t points) {
  Segment s;
  s.centroid = Eigen::Vector3f(x, y, 0.f);
  s.points.assign(points, Point{x, y, 0.f, 0.f});
  return s;
}

void expect_no_duplicates(const SegmentMap& map, float d) {
  const Segments& all = map.segments();
  std::set<uint64_t> ids;
  for (size_t a = 0; a < all.size(); ++a) {
    ids.insert(all[a].id);
    if (a > 0) {
      EXPECT_LT(all[a - 1].id, all[a].id) << "segments stay in id order";
    }
    for (size_t b = a + 1; b < all.size(); ++b)
      EXPECT_GE((all[a].centroid - all[b].centroid).norm(), d) << "segments " << a << " and " << b;
  }
  EXPECT_EQ(ids.size(), all.size());
}

}  // namespace

TEST(SegmentMap, AddsNewSegmentsAndReplacesByFullerViewsKeepingTheId) {
  SegmentMap map;
  EXPECT_EQ(map.add({segment(0, 0, 10), segment(5, 0, 10)}), 2u);
  EXPECT_EQ(map.add({segment(0.3f, 0, 8)}), 0u);  // smaller view: dropped
  EXPECT_FLOAT_EQ(map.segments()[0].centroid.x(), 0.f);
  EXPECT_EQ(map.add({segment(0.3f, 0, 12)}), 0u);  // fuller view: replaces, keeps id 0
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.segments()[0].id, 0u);
  EXPECT_FLOAT_EQ(map.segments()[0].centroid.x(), 0.3f);
  EXPECT_EQ(map.segments()[0].points.size(), 12u);
}

TEST(SegmentMap, AReplacementLandingOnAFullerSegmentIsDropped) {
  SegmentMap map(resolving());  // duplicate distance 1 m
  map.add({segment(0, 0, 10), segment(1.6f, 0, 20)});
  // Nearest is A (0.7 m, B is 0.9 m away): it replaces A, moving it within 0.9 m of B, which
  // has more points and stays.
  EXPECT_EQ(map.add({segment(0.7f, 0, 15)}), 0u);
  ASSERT_EQ(map.size(), 1u);
  EXPECT_EQ(map.segments()[0].id, 1u);
  EXPECT_EQ(map.segments()[0].points.size(), 20u);
  // The grid follows: a view near B merges into B, one farther away is new.
  EXPECT_EQ(map.add({segment(1.2f, 0, 5)}), 0u);
  EXPECT_EQ(map.add({segment(-0.5f, 0, 5)}), 1u);
  EXPECT_EQ(map.size(), 2u);
  expect_no_duplicates(map, 1.0f);
}

TEST(SegmentMap, AReplacementWithMorePointsRemovesTheSegmentsItLandedOn) {
  SegmentMap map(resolving());
  map.add({segment(0, 0, 10), segment(1.6f, 0, 20), segment(0.7f, 0.95f, 5), segment(10, 0, 1)});
  ASSERT_EQ(map.size(), 4u);
  // Replaces A (id 0) at (0.7, 0): B (0.9 m) and C (0.95 m) are now too close and smaller.
  EXPECT_EQ(map.add({segment(0.7f, 0, 25)}), 0u);
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.segments()[0].id, 0u);
  EXPECT_EQ(map.segments()[0].points.size(), 25u);
  EXPECT_EQ(map.segments()[1].id, 3u);
  // Grid still indexes the survivors at their current positions.
  EXPECT_EQ(map.add({segment(10.2f, 0, 2)}), 0u);
  EXPECT_EQ(map.segments()[1].points.size(), 2u);
  EXPECT_EQ(map.add({segment(1.5f, 0, 30)}), 0u) << "0.8 m from the kept segment";
  EXPECT_EQ(map.segments()[0].points.size(), 30u);
  expect_no_duplicates(map, 1.0f);
}

TEST(SegmentMap, EqualPointCountsKeepTheOlderSegment) {
  SegmentMap map(resolving());
  map.add({segment(0, 0, 10), segment(1.6f, 0, 15)});
  map.add({segment(0.7f, 0, 15)});  // replaces id 0, ties with id 1: id 0 (older) stays
  ASSERT_EQ(map.size(), 1u);
  EXPECT_EQ(map.segments()[0].id, 0u);
}

TEST(SegmentMap, NeverHoldsTwoSegmentsWithinTheDuplicateDistance) {
  SegmentMapConfig config = resolving();
  config.duplicate_distance_m = 1.0f;
  SegmentMap map(config);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.f, 12.f);
  std::uniform_int_distribution<size_t> points(1, 200);
  for (int batch = 0; batch < 60; ++batch) {
    Segments segments;
    for (int i = 0; i < 20; ++i) segments.push_back(segment(u(rng), u(rng), points(rng)));
    map.add(std::move(segments));
  }
  EXPECT_GT(map.size(), 30u);
  expect_no_duplicates(map, config.duplicate_distance_m);
}

TEST(SegmentMap, WithoutResolutionAReplacementMayLandNextToAnotherSegment) {
  SegmentMap map;  // the default keeps the previous behaviour
  map.add({segment(0, 0, 10), segment(1.6f, 0, 20)});
  map.add({segment(0.7f, 0, 15)});
  ASSERT_EQ(map.size(), 2u);
  EXPECT_LT((map.segments()[0].centroid - map.segments()[1].centroid).norm(), 1.0f);
}
