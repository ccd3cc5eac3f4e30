#include "segmatch/core/segmentation/segmenter.h"

#include <gtest/gtest.h>

#include "support/validation.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "segmatch/core/detail/random.h"

namespace segmatch {
namespace {

struct Scene {
  PointCloud cloud;
  std::vector<uint32_t> labels;
  std::vector<std::pair<size_t, size_t>> objects;  // [begin, end) per added object

  void add(float x, float y, float z, uint32_t label) {
    cloud.push_back({x, y, z, 0.f});
    labels.push_back(label);
  }
  void begin_object() { objects.emplace_back(cloud.size(), cloud.size()); }
  void end_object() { objects.back().second = cloud.size(); }

  // Sides and top of the box [x0, x0 + w] x [y0, y0 + w] x [z0, z0 + h], 0.1 m sampling.
  void box(float x0, float y0, float z0, float w, float h, uint32_t label) {
    begin_object();
    const int n = int(std::lround(w / 0.1f)), m = int(std::lround(h / 0.1f));
    for (int k = 0; k < m; ++k) {
      const float z = z0 + 0.1f * k;
      for (int i = 0; i <= n; ++i) {
        add(x0 + 0.1f * i, y0, z, label);
        add(x0 + 0.1f * i, y0 + w, z, label);
        if (i > 0 && i < n) {
          add(x0, y0 + 0.1f * i, z, label);
          add(x0 + w, y0 + 0.1f * i, z, label);
        }
      }
    }
    for (int i = 1; i < n; ++i) {
      for (int j = 1; j < n; ++j) add(x0 + 0.1f * i, y0 + 0.1f * j, z0 + h, label);
    }
    end_object();
  }

  // Vertical cylinder surface, about 0.1 m between samples.
  void cylinder(float cx, float cy, float radius, float h, uint32_t label) {
    begin_object();
    const int around = int(std::ceil(6.2831853f * radius / 0.1f));
    for (int k = 0; k < int(std::lround(h / 0.1f)); ++k) {
      for (int a = 0; a < around; ++a) {
        const float t = a * 6.2831853f / around;
        add(cx + radius * std::cos(t), cy + radius * std::sin(t), 0.1f * k, label);
      }
    }
    end_object();
  }
};

SegmenterConfig euclidean() { return SegmenterConfig{}; }
SegmenterConfig region_growing() {
  SegmenterConfig c;
  c.type = SegmenterType::kRegionGrowing;
  return c;
}

bool same_points(const PointCloud& a, const PointCloud& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].x != b[i].x || a[i].y != b[i].y || a[i].z != b[i].z) return false;
  }
  return true;
}

TEST(Segmenter, SeparatedObjectsGiveOneSegmentEach) {
  Scene s;
  s.box(0.f, 0.f, 0.f, 1.f, 1.f, 1);
  s.cylinder(3.f, 0.5f, 0.5f, 2.f, 2);
  s.box(5.f, 0.f, 0.f, 1.5f, 2.f, 3);
  s.cylinder(0.5f, 3.f, 0.3f, 3.f, 4);
  s.box(2.5f, 2.5f, 0.f, 1.f, 1.5f, 5);
  const Segments segments = segment_cloud(s.cloud, euclidean(), &s.labels);
  ASSERT_EQ(segments.size(), s.objects.size());
  for (size_t k = 0; k < segments.size(); ++k) {
    const auto [b, e] = s.objects[k];  // ids follow the smallest point index
    const PointCloud expected(s.cloud.begin() + b, s.cloud.begin() + e);
    EXPECT_EQ(segments[k].id, k);
    EXPECT_TRUE(same_points(segments[k].points, expected)) << "object " << k;
    EXPECT_EQ(segments[k].label, k + 1);
    Eigen::Vector3f mean = Eigen::Vector3f::Zero();
    for (const Point& p : expected) mean += p.xyz();
    EXPECT_LT((segments[k].centroid - mean / float(expected.size())).norm(), 1e-4);
  }
}

TEST(Segmenter, ObjectsCloserThanTheClusterDistanceMerge) {
  Scene close_pair, far_pair;
  close_pair.box(0.f, 0.f, 0.f, 1.f, 1.f, 1);
  close_pair.box(1.15f, 0.f, 0.f, 1.f, 1.f, 2);
  far_pair.box(0.f, 0.f, 0.f, 1.f, 1.f, 1);
  far_pair.box(1.3f, 0.f, 0.f, 1.f, 1.f, 2);
  const Segments merged = segment_cloud(close_pair.cloud, euclidean());
  ASSERT_EQ(merged.size(), 1u);
  EXPECT_EQ(merged[0].points.size(), close_pair.cloud.size());
  EXPECT_EQ(segment_cloud(far_pair.cloud, euclidean()).size(), 2u);
}

TEST(Segmenter, DiscardsSegmentsOutsideTheSizeRange) {
  Scene s;
  s.box(0.f, 0.f, 0.f, 0.3f, 0.3f, 1);  // 40 points
  s.box(2.f, 0.f, 0.f, 1.f, 1.f, 2);    // 481 points
  s.box(5.f, 0.f, 0.f, 2.f, 3.f, 3);    // 2761 points
  const auto size_of = [&](int k) { return s.objects[k].second - s.objects[k].first; };
  ASSERT_LT(size_of(0), 100u);
  SegmenterConfig config;
  config.max_points = 1000;
  Segments segments = segment_cloud(s.cloud, config, &s.labels);
  ASSERT_EQ(segments.size(), 1u);
  EXPECT_EQ(segments[0].label, 2u);
  EXPECT_EQ(segments[0].points.size(), size_of(1));
  EXPECT_EQ(segments[0].id, 0u);
  config.max_points = int(size_of(2));  // bounds are inclusive
  config.min_points = int(size_of(0));
  EXPECT_EQ(segment_cloud(s.cloud, config).size(), 3u);
}

TEST(Segmenter, LabelIsTheMostFrequentNonZeroLabel) {
  Scene s;
  s.box(0.f, 0.f, 0.f, 1.f, 1.f, 0);
  s.box(3.f, 0.f, 0.f, 1.f, 1.f, 0);
  for (size_t i = s.objects[0].first; i < s.objects[0].first + 50; ++i) s.labels[i] = 8;
  for (size_t i = s.objects[0].first + 50; i < s.objects[0].first + 90; ++i) s.labels[i] = 6;
  const Segments segments = segment_cloud(s.cloud, euclidean(), &s.labels);
  ASSERT_EQ(segments.size(), 2u);
  EXPECT_EQ(segments[0].label, 8u);  // 50 x 8 beat 40 x 6 and ~390 x 0
  EXPECT_EQ(segments[1].label, 0u);
  const Segments unlabeled = segment_cloud(s.cloud, euclidean());
  EXPECT_EQ(unlabeled[0].label, 0u);
}

TEST(Segmenter, OutputIsIndependentOfPointOrder) {
  Scene s;
  s.box(0.f, 0.f, 0.f, 1.f, 1.f, 1);
  s.cylinder(3.f, 0.5f, 0.5f, 2.f, 2);
  s.box(1.15f, 0.f, 0.f, 1.f, 0.5f, 3);
  Rng rng(5);
  PointCloud shuffled = s.cloud;
  for (size_t i = shuffled.size() - 1; i > 0; --i) std::swap(shuffled[i], shuffled[rng.index(i + 1)]);
  for (auto config : {euclidean(), region_growing()}) {
    config.min_points = 20;  // region growing cuts the boxes into their faces
    const auto canonical = [&](const PointCloud& cloud) {
      std::vector<std::vector<std::array<float, 3>>> sets;
      for (const Segment& seg : segment_cloud(cloud, config)) {
        sets.emplace_back();
        for (const Point& p : seg.points) sets.back().push_back({p.x, p.y, p.z});
        std::sort(sets.back().begin(), sets.back().end());
      }
      std::sort(sets.begin(), sets.end());
      return sets;
    };
    const auto a = canonical(s.cloud);
    EXPECT_FALSE(a.empty());
    EXPECT_EQ(a, canonical(shuffled));
    EXPECT_EQ(a, canonical(s.cloud));
  }
}

// A slab (roof overhang) touching the top of a wall: one Euclidean cluster, but two smooth
// surfaces.
TEST(Segmenter, RegionGrowingSplitsTouchingSurfacesThatEuclideanMerges) {
  Scene s;
  for (int i = 0; i <= 40; ++i) {
    for (int k = 0; k <= 30; ++k) s.add(0.f, 0.1f * i, 0.1f * k, 1);  // wall x = 0
  }
  for (int i = 0; i <= 40; ++i) {
    for (int j = 1; j <= 20; ++j) s.add(0.1f * j, 0.1f * i, 3.f, 2);  // slab at the top
  }
  EXPECT_EQ(segment_cloud(s.cloud, euclidean()).size(), 1u);
  const Segments segments = segment_cloud(s.cloud, region_growing(), &s.labels);
  ASSERT_EQ(segments.size(), 2u);
  EXPECT_EQ(segments[0].label, 1u);
  EXPECT_EQ(segments[1].label, 2u);
  for (const Segment& seg : segments) {
    const float expected_count = seg.label == 1 ? 41 * 31 : 41 * 20;
    int pure = 0;
    for (const Point& p : seg.points) pure += (seg.label == 1) == (p.x == 0.f);
    EXPECT_GT(pure, 0.97 * seg.points.size());
    EXPECT_GT(seg.points.size(), 0.85 * expected_count);
  }
}

TEST(Segmenter, RegionGrowingKeepsASmoothCurvedSurfaceWhole) {
  Scene s;
  s.cylinder(0.f, 0.f, 1.0f, 2.f, 1);
  const Segments segments = segment_cloud(s.cloud, region_growing());
  ASSERT_EQ(segments.size(), 1u);
  EXPECT_EQ(segments[0].points.size(), s.cloud.size());
}

TEST(Segmenter, ValidationNamesTheField) {
  const auto message = [](const SegmenterConfig& c) { return test::validation_message(c); };
  SegmenterConfig c;
  EXPECT_EQ(message(c), "");
  c.cluster_distance_m = 0.f;
  EXPECT_NE(message(c).find("cluster_distance_m"), std::string::npos);
  c = {};
  c.min_points = 0;
  EXPECT_NE(message(c).find("min_points"), std::string::npos);
  c = {};
  c.max_points = 10;
  EXPECT_NE(message(c).find("max_points"), std::string::npos);
  c = {};
  c.normal_radius_m = -1.f;
  EXPECT_NE(message(c).find("normal_radius_m"), std::string::npos);
  c = {};
  c.max_normal_angle_deg = 200.f;
  EXPECT_NE(message(c).find("max_normal_angle_deg"), std::string::npos);
  c = {};
  c.max_curvature = -1.f;
  EXPECT_NE(message(c).find("max_curvature"), std::string::npos);
  c = {};
  c.min_normal_neighbours = 1;
  EXPECT_NE(message(c).find("min_normal_neighbours"), std::string::npos);
  EXPECT_THROW(segment_cloud({{0.f, 0.f, 0.f, 0.f}}, c), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
