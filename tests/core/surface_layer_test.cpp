// The map's surface layer (SurfaceAccumulator): one point per occupied voxel, in the world
// frame, each scan cut at max_range_m; the same scan added twice does not grow the layer.
#include "segmatch/core/mapping/surface_layer.h"

#include "segmatch/core/preprocess/preprocess.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <tuple>

namespace segmatch {
namespace {

// A flat square of ground around the sensor, 2 cm spacing, 1.8 m below it.
PointCloud ground_scan(float half_m) {
  PointCloud scan;
  for (float x = -half_m; x <= half_m; x += 0.02f)
    for (float y = -half_m; y <= half_m; y += 0.02f) scan.push_back({x, y, -1.8f, 7.f});
  return scan;
}

TEST(SurfaceLayer, OnePointPerVoxelInTheWorldFrameWithinRange) {
  SurfaceLayerConfig c;
  c.enabled = true;
  c.leaf_m = 0.5f;
  c.max_range_m = 10.0f;
  SurfaceAccumulator layer(c);
  Pose3d T = Pose3d::Identity();
  T.translation() = Eigen::Vector3d(100.0, -50.0, 2.0);
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const PointCloud scan = ground_scan(15.f);
  layer.add_scan(scan, T);
  const PointCloud points = layer.points();
  ASSERT_FALSE(points.empty());
  std::set<std::tuple<int, int, int>> voxels;
  for (const Point& p : points) {
    EXPECT_NEAR(p.z, 0.2f, 1e-4f) << "the ground 1.8 m below a sensor at 2 m";
    EXPECT_LE(std::hypot(p.x - 100.f, p.y + 50.f), 10.f + 0.5f) << "cut at max_range_m (plus a voxel)";
    EXPECT_EQ(p.intensity, 0.f);
    EXPECT_TRUE(
        voxels.emplace(int(std::floor(p.x / 0.5f)), int(std::floor(p.y / 0.5f)), int(std::floor(p.z / 0.5f))).second)
        << "one point per voxel";
  }
  // A disc of radius 10 m holds about pi * 10^2 / 0.25 voxels of 0.5 m, give or take the
  // ring of voxels its edge cuts (2 pi 10 / 0.5).
  EXPECT_NEAR(static_cast<double>(points.size()), M_PI * 100.0 / 0.25, 2.0 * M_PI * 10.0 / 0.5);
  layer.add_scan(scan, T);  // the same scan again: the same voxels
  EXPECT_EQ(layer.points().size(), points.size());
  EXPECT_EQ(layer.scans(), 2u);
}

TEST(SurfaceLayer, OffMeansEmptyAndBadValuesAreRefusedByName) {
  SurfaceLayerConfig c;
  c.enabled = false;
  SurfaceAccumulator off(c);
  off.add_scan(ground_scan(5.f), Pose3d::Identity());
  EXPECT_TRUE(off.points().empty());
  c = {};
  c.leaf_m = -1.f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.tile_m = 0.1f;  // smaller than a voxel
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.max_range_m = std::nanf("");
  EXPECT_THROW(SurfaceAccumulator{c}, std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
