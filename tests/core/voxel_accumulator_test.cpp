// VoxelAccumulator equals voxel_filter(LocalCloud::crop(...)) for the same scans: same voxels in
// the same order, centroids and intensities up to float summation order, same majority labels,
// including crops after scans left the cylinder (and were subtracted) and voxels cut by the
// cylinder's boundary (the crop is by raw point, not by voxel centroid).
#include "segmatch/core/preprocess/voxel_accumulator.h"

#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/preprocess/preprocess.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>

using namespace segmatch;

namespace {

Pose3d pose(double x, double y, double z, double yaw) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// A static world of clustered "surface" anchors along a street (x in [-10, 90]); each scan
// sees anchors within range_m of the sensor with noise, so voxels collect points from many
// scans, and labels are mixed (some 0, some of a neighbour, so votes tie) within voxels.
struct Scene {
  std::vector<Eigen::Vector3d> anchors;
  std::vector<uint32_t> anchor_label;
  Eigen::Vector3d offset;

  explicit Scene(Eigen::Vector3d world_offset = Eigen::Vector3d::Zero()) : offset(world_offset) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> ux(-10, 90), uy(-25, 25), uz(0, 6);
    for (int i = 0; i < 30000; ++i) {
      anchors.emplace_back(ux(rng), uy(rng), i % 3 == 0 ? 0.0 : uz(rng));
      anchor_label.push_back(static_cast<uint32_t>(1 + (i / 50) % 40) << 16 | 10u);
    }
  }

  void scan(const Pose3d& T_world_sensor, double range_m, size_t n, uint32_t seed, PointCloud* points,
            std::vector<uint32_t>* labels) const {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<size_t> pick(0, anchors.size() - 1);
    std::normal_distribution<double> noise(0.0, 0.03);
    std::uniform_real_distribution<double> u(0, 1);
    const Pose3d T_sensor_world = T_world_sensor.inverse();
    points->clear();
    labels->clear();
    while (points->size() < n) {
      const size_t a = pick(rng);
      const Eigen::Vector3d w = anchors[a] + offset + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      if ((w - T_world_sensor.translation()).head<2>().norm() > range_m) continue;
      const Eigen::Vector3d s = T_sensor_world * w;
      points->push_back({float(s.x()), float(s.y()), float(s.z()), float(u(rng))});
      const double r = u(rng);
      labels->push_back(r < 0.15 ? 0u : r < 0.3 ? anchor_label[(a + 50) % anchors.size()] : anchor_label[a]);
    }
  }
};

void expect_same(const PointCloud& expected, const std::vector<uint32_t>& expected_labels, const PointCloud& got,
                 const std::vector<uint32_t>& got_labels, const char* what) {
  ASSERT_EQ(got.size(), expected.size()) << what;
  ASSERT_EQ(got_labels.size(), expected_labels.size()) << what;
  // Float summation order only (and the final rounding to float: a float's ulp is 8 um at
  // 100 m, 16 mm at 150 km).
  size_t bad = 0;
  for (size_t i = 0; i < expected.size() && bad < 5; ++i) {
    const float m = std::max({std::abs(expected[i].x), std::abs(expected[i].y), std::abs(expected[i].z)});
    const float tol = 2e-5f + 2.0f * (std::nextafter(m, std::numeric_limits<float>::infinity()) - m);
    const bool same = std::abs(got[i].x - expected[i].x) <= tol && std::abs(got[i].y - expected[i].y) <= tol &&
                      std::abs(got[i].z - expected[i].z) <= tol &&
                      std::abs(got[i].intensity - expected[i].intensity) <= 1e-5f &&
                      got_labels[i] == expected_labels[i];
    if (!same) {
      ++bad;
      ADD_FAILURE() << what << ": voxel " << i << " expected (" << expected[i].x << ", " << expected[i].y << ", "
                    << expected[i].z << ", i " << expected[i].intensity << ", label " << expected_labels[i] << ") got ("
                    << got[i].x << ", " << got[i].y << ", " << got[i].z << ", i " << got[i].intensity << ", label "
                    << got_labels[i] << ")";
    }
  }
}

// Drives along x (turning back after `turn` scans), feeding both the reference (LocalCloud +
// voxel_filter) and the accumulator, cropping every `crop_every` scans; returns the number of
// crops after which scans had been dropped. With evict_every_scan the accumulator evicts after
// every scan and the reference crops (output unused) after every scan.
size_t drive_and_compare(const Scene& scene, LocalCloudConfig lc, double step_m, int scans, int crop_every,
                         bool some_without_labels, bool with_nan, int turn = 1 << 30, bool evict_every_scan = false) {
  const VoxelGridConfig vc;
  LocalCloud reference(lc);
  VoxelAccumulator acc(lc, vc);
  size_t crops_after_drops = 0, added = 0;
  PointCloud points;
  std::vector<uint32_t> labels;
  for (int k = 0; k < scans; ++k) {
    const Pose3d T = pose(scene.offset.x() + (k < turn ? k : 2 * turn - k) * step_m,
                          scene.offset.y() + 0.3 * std::sin(0.2 * k), scene.offset.z() + 1.73, 0.05 * k);
    scene.scan(T, 30.0, 6000, 100 + k, &points, &labels);
    if (with_nan) points[k % points.size()].x = std::numeric_limits<float>::quiet_NaN();
    const bool labelled = !(some_without_labels && k % 4 == 1);
    const bool a = reference.add_scan(points, T, labelled ? &labels : nullptr);
    const bool b = acc.add_scan(points, T, labelled ? &labels : nullptr);
    EXPECT_EQ(a, b) << "scan " << k;
    added += a;
    if (evict_every_scan) {
      acc.evict(T);
      reference.crop(T);
      EXPECT_EQ(acc.scan_count(), reference.scan_count()) << "scan " << k;
    }
    if (k % crop_every != crop_every - 1 && k != scans - 1) continue;
    std::vector<uint32_t> cropped_labels, expected_labels, got_labels;
    const PointCloud cropped = reference.crop(T, &cropped_labels);
    const PointCloud expected = voxel_filter(cropped, vc, &cropped_labels, &expected_labels);
    const PointCloud got = acc.crop(T, &got_labels);
    EXPECT_EQ(acc.scan_count(), reference.scan_count()) << "scan " << k;
    EXPECT_EQ(acc.point_count(), reference.point_count()) << "scan " << k;
    EXPECT_GT(expected.size(), 300u);
    expect_same(expected, expected_labels, got, got_labels, ("crop at scan " + std::to_string(k)).c_str());
    // Without labels requested: the same voxels.
    const PointCloud unlabelled = acc.crop(T);
    EXPECT_EQ(unlabelled.size(), got.size());
    if (reference.scan_count() < added) ++crops_after_drops;
  }
  return crops_after_drops;
}

}  // namespace

TEST(VoxelAccumulator, EqualsVoxelFilterOfTheCroppedLocalCloudIncludingDroppedScans) {
  const Scene scene;
  LocalCloudConfig lc;
  lc.radius_m = 20.0;  // points reach 30 m: a scan leaves once the vehicle is ~50 m past it
  // Out to x = 70 and back to x = 20: the scans of the start left the cylinder (and were
  // subtracted) before the vehicle returned to where their points lie.
  const size_t crops_after_drops = drive_and_compare(scene, lc, 1.0, 121, 3, false, false, 70);
  EXPECT_GE(crops_after_drops, 20u) << "scans left the cylinder and were subtracted";
}

// Scans leaving by age, on a route that returns: the accumulator drops and subtracts the same
// scans as LocalCloud.
TEST(VoxelAccumulator, EqualsTheLocalCloudWhenScansLeaveByAge) {
  const Scene scene;
  LocalCloudConfig lc;
  lc.radius_m = 40.0;  // the cylinder alone would keep most scans
  lc.max_scan_age_m = 15.0;
  const size_t crops_after_drops = drive_and_compare(scene, lc, 1.0, 121, 3, false, false, 70);
  EXPECT_GE(crops_after_drops, 30u) << "scans left by age and were subtracted";
}

// A vehicle evicts after every scan (moving the subtraction of old scans off its queries):
// the same as cropping at every scan, and crops far apart still equal the reference.
TEST(VoxelAccumulator, EvictingAfterEveryScanEqualsCroppingAtEveryScan) {
  const Scene scene;
  LocalCloudConfig lc;
  lc.radius_m = 20.0;
  const size_t crops_after_drops = drive_and_compare(scene, lc, 1.0, 121, 10, false, false, 70, true);
  EXPECT_GE(crops_after_drops, 6u);
}

TEST(VoxelAccumulator, EqualsWithSubsamplingSkippedScansMissingLabelsAndNaNs) {
  const Scene scene;
  LocalCloudConfig lc;
  lc.radius_m = 15.0;
  lc.subsample_leaf_m = 0.05;
  lc.min_travel_between_scans_m = 1.0;
  // 0.7 m steps: every other scan or so is refused by both.
  const size_t crops_after_drops = drive_and_compare(scene, lc, 0.7, 100, 4, true, true);
  EXPECT_GE(crops_after_drops, 3u);
}

TEST(VoxelAccumulator, EqualsFarFromTheOriginWhereVoxelKeysWrap) {
  // 150 km east, 130 km south: beyond 2^20 voxels per axis from the origin.
  const Scene scene(Eigen::Vector3d(150000.0, -130000.0, 250.0));
  LocalCloudConfig lc;
  lc.radius_m = 20.0;
  drive_and_compare(scene, lc, 1.0, 30, 5, false, false);
}

// The crop is by raw point, as LocalCloud::crop, not by voxel centroid: a voxel cut by the
// boundary keeps the centroid (and count) of its points inside. A crop by voxel centroid would
// keep the first voxel below with all 3 points and centroid (9.94, 1.04), and the second with
// 3 points although only 1 lies inside (so voxel_filter drops it: < 2 points).
TEST(VoxelAccumulator, VoxelsCutByTheCylinderKeepOnlyTheirPointsInside) {
  LocalCloudConfig lc;
  lc.radius_m = 10.0;
  const VoxelGridConfig vc;
  const PointCloud scan = {
      {9.91f, 1.01f, 0.05f, 1.f}, {9.92f, 1.02f, 0.05f, 1.f}, {9.99f, 1.09f, 0.05f, 1.f},  // 2 in, 1 out
      {9.81f, 1.51f, 0.05f, 1.f}, {9.89f, 1.59f, 0.05f, 1.f}, {9.88f, 1.58f, 0.05f, 1.f},  // 1 in, 2 out
      {0.51f, 0.51f, 0.05f, 1.f}, {0.52f, 0.52f, 0.05f, 3.f},                              // well inside
  };
  for (const Point& p : {scan[0], scan[1], scan[3]}) ASSERT_LE(std::hypot(p.x, p.y), 10.0f);
  for (const Point& p : {scan[2], scan[4], scan[5]}) ASSERT_GT(std::hypot(p.x, p.y), 10.0f);
  ASSERT_LT(std::hypot(9.94, 1.04), 10.0) << "the 3-point centroid is inside";
  ASSERT_LT(std::hypot(9.86, 1.56), 10.0) << "the 3-point centroid is inside";

  VoxelAccumulator acc(lc, vc);
  ASSERT_TRUE(acc.add_scan(scan, Pose3d::Identity()));
  const PointCloud got = acc.crop(Pose3d::Identity());
  LocalCloud reference(lc);
  reference.add_scan(scan, Pose3d::Identity());
  const PointCloud expected = voxel_filter(reference.crop(Pose3d::Identity()), vc);
  ASSERT_EQ(got.size(), 2u);
  ASSERT_EQ(expected.size(), 2u);
  EXPECT_NEAR(got[0].x, 0.515f, 1e-5f);
  EXPECT_NEAR(got[0].intensity, 2.0f, 1e-6f);
  EXPECT_NEAR(got[1].x, 9.915f, 1e-5f) << "centroid of the 2 points inside, not of all 3";
  EXPECT_NEAR(got[1].y, 1.015f, 1e-5f);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_NEAR(got[i].x, expected[i].x, 1e-5f);
    EXPECT_NEAR(got[i].y, expected[i].y, 1e-5f);
    EXPECT_NEAR(got[i].z, expected[i].z, 1e-5f);
  }
}

TEST(VoxelAccumulator, ClearAndRefusals) {
  VoxelAccumulator acc;
  PointCloud scan = {{1.05f, 1.05f, 1.05f, 0.f}, {1.06f, 1.06f, 1.06f, 0.f}};
  std::vector<uint32_t> wrong_size = {1u};
  EXPECT_THROW(acc.add_scan(scan, Pose3d::Identity(), &wrong_size), std::invalid_argument);
  EXPECT_TRUE(acc.add_scan(scan, Pose3d::Identity()));
  EXPECT_FALSE(acc.add_scan(scan, Pose3d::Identity())) << "did not move";
  EXPECT_EQ(acc.voxel_count(), 1u);
  EXPECT_EQ(acc.crop(Pose3d::Identity()).size(), 1u);
  acc.clear();
  EXPECT_EQ(acc.scan_count(), 0u);
  EXPECT_EQ(acc.voxel_count(), 0u);
  EXPECT_TRUE(acc.crop(Pose3d::Identity()).empty());
  PointCloud far = {{0.f, 30000.f, 0.f, 0.f}};
  EXPECT_THROW(acc.add_scan(far, Pose3d::Identity()), std::invalid_argument);
  LocalCloudConfig bad;
  bad.radius_m = -1;
  EXPECT_THROW(VoxelAccumulator{bad}, std::invalid_argument);
}
