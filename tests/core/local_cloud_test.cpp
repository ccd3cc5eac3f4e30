#include "segmatch/core/localization/local_cloud.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "segmatch/core/detail/random.h"
#include "support/validation.h"

namespace segmatch {
namespace {

PointCloud random_scan(Rng& rng, int n, double extent) {
  PointCloud scan(n);
  for (auto& p : scan) {
    p = {float(rng.uniform(-extent, extent)), float(rng.uniform(-extent, extent)), float(rng.uniform(-2.0, 2.0)),
         float(rng.uniform())};
  }
  return scan;
}

Pose3d pose_at(double x, double y, double yaw) {
  Pose3d T = Pose3d::Identity();
  T.translate(Eigen::Vector3d(x, y, 0.5));
  T.rotate(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
  return T;
}

TEST(LocalCloud, FirstScanAlwaysAddedThenOnlyEveryMetre) {
  LocalCloud cloud;
  const PointCloud scan = {{1.f, 2.f, 3.f, 0.f}};
  int added = 0;
  for (int step = 0; step <= 20; ++step) {  // 0.25 m steps over 5 m
    const bool was_added = cloud.add_scan(scan, pose_at(0.25 * step, 0.0, 0.0));
    EXPECT_EQ(was_added, step % 4 == 0) << "step " << step;
    added += was_added;
  }
  EXPECT_EQ(added, 6);
  EXPECT_EQ(cloud.scan_count(), 6u);
  EXPECT_EQ(cloud.point_count(), 6u);
  cloud.clear();
  EXPECT_EQ(cloud.scan_count(), 0u);
  EXPECT_TRUE(cloud.add_scan(scan, pose_at(0.1, 0.0, 0.0)));  // first after clear
}

TEST(LocalCloud, TransformsScansIntoWorldFrame) {
  LocalCloud cloud;
  const PointCloud scan = {{1.f, 0.f, 0.f, 7.f}, {0.f, 2.f, 1.f, 8.f}};
  cloud.add_scan(scan, pose_at(10.0, 5.0, M_PI / 2));  // yaw 90 deg, sensor at z = 0.5
  const PointCloud out = cloud.crop(pose_at(10.0, 5.0, 0.0));
  ASSERT_EQ(out.size(), 2u);
  EXPECT_NEAR(out[0].x, 10.f, 1e-5);
  EXPECT_NEAR(out[0].y, 6.f, 1e-5);
  EXPECT_NEAR(out[0].z, 0.5f, 1e-5);
  EXPECT_EQ(out[0].intensity, 7.f);
  EXPECT_NEAR(out[1].x, 8.f, 1e-5);
  EXPECT_NEAR(out[1].y, 5.f, 1e-5);
  EXPECT_NEAR(out[1].z, 1.5f, 1e-5);
}

TEST(LocalCloud, CropKeepsExactlyThePointsWithinRadius) {
  LocalCloudConfig config;
  config.radius_m = 15.0;
  LocalCloud cloud(config);
  Rng rng(42);
  PointCloud all_world;
  for (int s = 0; s < 8; ++s) {
    const PointCloud scan = random_scan(rng, 2000, 20.0);
    const Pose3d T = pose_at(3.0 * s, 0.5 * s, 0.3 * s);
    ASSERT_TRUE(cloud.add_scan(scan, T));
    for (const Point& p : scan) {
      const Eigen::Vector3d w = T * Eigen::Vector3d(p.x, p.y, p.z);
      all_world.push_back({float(w.x()), float(w.y()), float(w.z()), p.intensity});
    }
  }
  const Pose3d center = pose_at(10.0, 1.0, 1.0);
  PointCloud expected;
  for (const Point& p : all_world) {
    const double dx = p.x - 10.0, dy = p.y - 1.0;
    if (dx * dx + dy * dy <= 15.0 * 15.0) expected.push_back(p);
  }
  const PointCloud out = cloud.crop(center);
  ASSERT_EQ(out.size(), expected.size());
  ASSERT_GT(out.size(), 1000u);
  ASSERT_LT(out.size(), all_world.size());
  for (size_t i = 0; i < out.size(); ++i) {
    EXPECT_NEAR(out[i].x, expected[i].x, 1e-4);
    EXPECT_NEAR(out[i].y, expected[i].y, 1e-4);
    EXPECT_NEAR(out[i].z, expected[i].z, 1e-4);
  }
}

TEST(LocalCloud, DropsScansOutsideTheCylinder) {
  LocalCloudConfig config;
  config.radius_m = 10.0;
  LocalCloud cloud(config);
  const PointCloud scan = {{1.f, 0.f, 0.f, 0.f}, {-1.f, 0.f, 0.f, 0.f}};
  for (int s = 0; s < 5; ++s) cloud.add_scan(scan, pose_at(5.0 * s, 0.0, 0.0));
  EXPECT_EQ(cloud.scan_count(), 5u);
  const PointCloud out = cloud.crop(pose_at(20.0, 0.0, 0.0));  // scans at 0 and 5 are far
  EXPECT_EQ(cloud.scan_count(), 3u);
  EXPECT_EQ(out.size(), 5u);  // x = 11, 14, 16, 19, 21 (x = 9 is 11 m away)
}

// A scan leaves once the vehicle drove more than max_scan_age_m since it was added, even with
// its points still in the cylinder (the odometry that placed it drifted since).
TEST(LocalCloud, DropsScansOlderThanTheirMaximumAge) {
  LocalCloudConfig config;
  config.radius_m = 100.0;  // every scan stays within the cylinder
  config.max_scan_age_m = 10.0;
  LocalCloud cloud(config);
  const PointCloud scan = {{1.f, 0.f, 0.f, 0.f}, {-1.f, 0.f, 0.f, 0.f}};
  for (int s = 0; s < 5; ++s) cloud.add_scan(scan, pose_at(5.0 * s, 0.0, 0.0));
  const PointCloud out = cloud.crop(pose_at(20.0, 0.0, 0.0));  // driven 20 m: scans at 0 and 5 are too old
  EXPECT_EQ(cloud.scan_count(), 3u);
  EXPECT_EQ(out.size(), 6u);
  config.max_scan_age_m = 0.0;  // no age limit: the cylinder alone decides
  LocalCloud unbounded(config);
  for (int s = 0; s < 5; ++s) unbounded.add_scan(scan, pose_at(5.0 * s, 0.0, 0.0));
  unbounded.crop(pose_at(20.0, 0.0, 0.0));
  EXPECT_EQ(unbounded.scan_count(), 5u);
}

TEST(LocalCloud, CarriesLabels) {
  LocalCloud cloud;
  const PointCloud scan = {{1.f, 0.f, 0.f, 0.f}, {2.f, 0.f, 0.f, 0.f}, {200.f, 0.f, 0.f, 0.f}};
  const std::vector<uint32_t> labels = {11, 12, 13};
  cloud.add_scan(scan, pose_at(0.0, 0.0, 0.0), &labels);
  cloud.add_scan(scan, pose_at(2.0, 0.0, 0.0));  // no labels -> 0
  std::vector<uint32_t> labels_out;
  const PointCloud out = cloud.crop(pose_at(0.0, 0.0, 0.0), &labels_out);
  ASSERT_EQ(out.size(), 4u);
  EXPECT_EQ(labels_out, (std::vector<uint32_t>{11, 12, 0, 0}));
  const std::vector<uint32_t> bad = {1};
  EXPECT_THROW(cloud.add_scan(scan, pose_at(9.0, 0.0, 0.0), &bad), std::invalid_argument);
}

TEST(LocalCloud, SubsamplesEachScan) {
  LocalCloudConfig config;
  config.subsample_leaf_m = 1.0;
  LocalCloud cloud(config);
  PointCloud scan;
  for (int i = 0; i < 10; ++i) scan.push_back({0.05f * i + 0.01f, 0.2f, 0.3f, float(i)});
  scan.push_back({5.5f, 0.2f, 0.3f, 99.f});
  scan.push_back({NAN, 0.f, 0.f, 0.f});
  cloud.add_scan(scan, Pose3d::Identity());
  const PointCloud out = cloud.crop(Pose3d::Identity());
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].intensity, 0.f);  // first point of its cube
  EXPECT_EQ(out[1].intensity, 99.f);
}

TEST(LocalCloud, ValidationNamesTheField) {
  const auto message = [](const LocalCloudConfig& c) { return test::validation_message(c); };
  LocalCloudConfig c;
  EXPECT_EQ(message(c), "");
  c.radius_m = 0.0;
  EXPECT_NE(message(c).find("radius_m"), std::string::npos);
  c = {};
  c.min_travel_between_scans_m = -1.0;
  EXPECT_NE(message(c).find("min_travel_between_scans_m"), std::string::npos);
  c = {};
  c.subsample_leaf_m = NAN;
  EXPECT_NE(message(c).find("subsample_leaf_m"), std::string::npos);
  LocalCloudConfig bad;
  bad.radius_m = -5.0;
  EXPECT_THROW(LocalCloud{bad}, std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
