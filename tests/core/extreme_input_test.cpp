// Valid but extreme inputs: an empty cloud, a million points in one voxel, a city
// 10,000 km from the origin, a segment of one point. Each gets an answer (a pose or a typed
// refusal) with finite numbers; nothing throws, crashes or hangs.
#include "segmatch/core/description/descriptors.h"
#include "segmatch/core/localization/localizer.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <cstdio>

namespace segmatch {
namespace {

LocalizerConfig street_config() { return test::street_localizer_config(); }

PointCloud shifted(PointCloud cloud, const Eigen::Vector3f& by) {
  for (Point& p : cloud) p.x += by.x(), p.y += by.y(), p.z += by.z();
  return cloud;
}

void expect_finite(const LocalizationResult& r) {
  EXPECT_TRUE(r.T_map_query.matrix().allFinite());
  EXPECT_TRUE(std::isfinite(r.confidence));
  for (const Segment& s : r.query) {
    EXPECT_TRUE(s.centroid.allFinite());
    for (float v : s.eigen) EXPECT_TRUE(std::isfinite(v));
  }
}

TEST(ExtremeInput, EmptyCloudIsATypedRefusal) {
  const LocalizerConfig c = street_config();
  const Localizer localizer(c, extract_segments(test::pole_street(true), Eigen::Vector3f(25, 0, 2), c.segmentation));
  const LocalizationResult r = localizer.localize(PointCloud{}, Eigen::Vector3f::Zero());
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kTooFewSegments) << r.reason;
  EXPECT_EQ(r.query_segments, 0u);
  EXPECT_TRUE(voxel_filter(PointCloud{}, c.segmentation.voxel).empty());
}

TEST(ExtremeInput, AMillionPointsInOneVoxel) {
  const LocalizerConfig c = street_config();
  const PointCloud street = test::pole_street(true);
  PointCloud query = street;
  for (int i = 0; i < 1000000; ++i) query.push_back({30.01f + 1e-6f * float(i % 1000), -3.02f, 1.03f, 0.f});
  EXPECT_EQ(voxel_filter(PointCloud(query.end() - 1000000, query.end()), c.segmentation.voxel).size(), 1u);
  const Localizer localizer(c, extract_segments(street, Eigen::Vector3f(25, 0, 2), c.segmentation));
  const LocalizationResult r = localizer.localize(query, Eigen::Vector3f(25, 0, 2));
  expect_finite(r);
  ASSERT_TRUE(r.localized()) << r.reason;  // one extra voxel does not hide the street
  EXPECT_LT(r.T_map_query.translation().norm(), 0.05);
}

// At 1e7 m a float's step is 1 m: every point of the street falls on a 1 m lattice, so no 0.1 m
// segment survives. The answer must still be a refusal with finite numbers, not a crash or NaN.
TEST(ExtremeInput, CityTenThousandKilometresFromTheOrigin) {
  const LocalizerConfig c = street_config();
  for (const float far : {1e7f, -1e7f}) {
    const Eigen::Vector3f offset(far, -far, 0.f);
    const PointCloud street = shifted(test::pole_street(true), offset);
    const Segments map = extract_segments(street, Eigen::Vector3f(25, 0, 2) + offset, c.segmentation);
    for (const Segment& s : map) EXPECT_TRUE(s.centroid.allFinite());
    std::printf("[extreme] street at %g m: %zu map segments (%zu at the origin)\n", double(far), map.size(),
                extract_segments(test::pole_street(true), Eigen::Vector3f(25, 0, 2), c.segmentation).size());
    if (map.empty()) continue;  // nothing to localize against: the Localizer refuses an empty map
    const Localizer localizer(c, map);
    const LocalizationResult r = localizer.localize(street, Eigen::Vector3f(25, 0, 2) + offset);
    expect_finite(r);
    std::printf("[extreme]   %s: %s\n", r.localized() ? "localized" : "refused", r.reason.c_str());
    if (r.localized()) {
      EXPECT_LT(r.T_map_query.translation().norm(), 2.0);  // within the float step
    }
  }
}

TEST(ExtremeInput, SegmentOfOnePointHasZeroDescriptors) {
  const PointCloud one = {{1.f, 2.f, 3.f, 0.5f}};
  for (float v : eigen_features(one)) EXPECT_EQ(v, 0.f);
  for (float v : esf_descriptor(one, 100, 1)) EXPECT_EQ(v, 0.f);
  Segments segments(1);
  segments[0].points = one;
  DescriptorConfig config;
  describe_segments(segments, config);
  EXPECT_EQ(segments[0].centroid, Eigen::Vector3f(1.f, 2.f, 3.f));
  for (float v : segments[0].eigen) EXPECT_EQ(v, 0.f);
  for (float v : segments[0].esf) EXPECT_EQ(v, 0.f);
}

}  // namespace
}  // namespace segmatch
