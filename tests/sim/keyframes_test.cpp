// Tests of the SLAM-style keyframe export: the folder io::Sequence reads, the spacing of
// keyframes and points, the frames of poses and points, the odometry drift, and the export
// from generate_dataset and segmatch-sim.
#include "segmatch/sim/keyframes.h"
#include "segmatch/sim/dataset.h"

#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/io/sequence.h"
#include "support/run_command.h"

#include <gtest/gtest.h>

#include "sim_test_util.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace segmatch::sim {
namespace {
namespace fs = std::filesystem;

constexpr uint32_t kGround = 40;

using segmatch::sim_test::read_all;
using segmatch::sim_test::TempDir;

// A 40 m street: ground, two facades 6 m either side and a pole every 4 m.
Scene street() {
  Scene s = {Primitive::triangle({-20, -30, 0}, {80, -30, 0}, {80, 30, 0}, kGround, 0.3f),
             Primitive::triangle({-20, -30, 0}, {80, 30, 0}, {-20, 30, 0}, kGround, 0.3f),
             Primitive::box({30, 7, 5}, {50, 1, 5}, 0.0f, (1u << 16) | 50u, 0.6f),
             Primitive::box({30, -7, 5}, {50, 1, 5}, 0.0f, (2u << 16) | 50u, 0.6f)};
  for (int i = 0; i < 12; ++i)
    s.push_back(Primitive::cylinder({float(4 * i), 4.5f, 0}, 0.15f, 4.0f, (uint32_t(10 + i) << 16) | 80u, 0.8f));
  return s;
}

// Walking along the street at 1.5 m/s, sensor 1 m up, a frame every 0.1 s.
Traversal walk(double length_m) {
  Traversal t;
  for (int i = 0; i * 0.15 <= length_m; ++i) {
    Pose3d T = Pose3d::Identity();
    T.translation() = Eigen::Vector3d(0.15 * i, 0.02 * std::sin(0.3 * i), 1.0);
    T.linear() = Eigen::AngleAxisd(0.02 * std::sin(0.1 * i), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    t.times_s.push_back(0.1 * i);
    t.T_world_lidar.push_back(T);
    t.odometer_m.push_back(0.15 * i);
  }
  return t;
}

struct Exported {
  Traversal traversal = walk(30.0);
  KeyframeSummary summary;
};

Exported export_walk(const fs::path& dir, const KeyframeConfig& c) {
  const RayCaster caster(street());
  const LidarModel model = livox_avia();
  Exported e;
  const ScanSource simulate = [&](size_t f) {
    return simulate_scan(caster, model, e.traversal.T_world_lidar[f], f, 100.0 + e.traversal.times_s[f]);
  };
  e.summary = write_keyframes(e.traversal, simulate, c, dir.string());
  return e;
}

KeyframeConfig every(double m, int frames) {
  KeyframeConfig c;
  c.every_m = m;
  c.frames = frames;
  c.leaf_m = 0.2f;
  return c;
}

// Median distance from a sample of points to their nearest other point.
double median_spacing(const PointCloud& cloud) {
  std::vector<double> nearest;
  for (size_t i = 0; i < cloud.size(); i += 13) {
    double best = 1e9;
    for (size_t j = 0; j < cloud.size(); ++j)
      if (j != i) best = std::min(best, double((cloud[i].xyz() - cloud[j].xyz()).norm()));
    nearest.push_back(best);
  }
  std::nth_element(nearest.begin(), nearest.begin() + nearest.size() / 2, nearest.end());
  return nearest[nearest.size() / 2];
}

TEST(Keyframes, SequenceReaderLoadsTheFolder) {
  TempDir dir("segmatch_keyframes_test_");
  const Exported e = export_walk(dir.path(), every(3.0, 5));
  const io::Sequence seq = io::Sequence::open(dir.path().string());
  EXPECT_EQ(seq.layout(), io::SequenceLayout::kPcdKeyframes);
  ASSERT_EQ(seq.size(), e.summary.frames.size());
  ASSERT_GE(seq.size(), 8u);
  EXPECT_TRUE(seq.has_times());
  EXPECT_TRUE(seq.has_labels());
  EXPECT_TRUE(seq.poses()[0].isApprox(Pose3d::Identity(), 1e-15)) << "world = first keyframe";
  const Pose3d T_kf0_world = e.summary.T_world_keyframe[0].inverse();
  for (size_t k = 0; k < seq.size(); ++k) {
    EXPECT_TRUE(seq.poses()[k].isApprox(T_kf0_world * e.summary.T_world_keyframe[k], 1e-9)) << k;
    EXPECT_NEAR(seq.times()[k], e.traversal.times_s[e.summary.frames[k]], 1e-9);
  }
  const io::Sequence odom = io::Sequence::open(dir.path().string(), {(dir.path() / "odom_poses.txt").string()});
  EXPECT_EQ(odom.size(), seq.size());
}

TEST(Keyframes, SpacedByEveryMetresAndFirstHasAllItsFrames) {
  TempDir dir("segmatch_keyframes_test_");
  const Exported e = export_walk(dir.path(), every(3.0, 5));
  ASSERT_FALSE(e.summary.frames.empty());
  EXPECT_EQ(e.summary.frames[0], 4u) << "the first keyframe integrates frames 0..4";
  for (size_t k = 1; k < e.summary.frames.size(); ++k) {
    const double d =
        (e.summary.T_world_keyframe[k].translation() - e.summary.T_world_keyframe[k - 1].translation()).norm();
    EXPECT_GE(d, 3.0) << k;
    EXPECT_LT(d, 3.0 + 0.16) << k << ": within one 0.15 m step of the threshold";
  }
}

TEST(Keyframes, PointsAreOnePerVoxelAtAboutTheLeafSpacingInTheSensorFrame) {
  TempDir dir("segmatch_keyframes_test_");
  export_walk(dir.path(), every(3.0, 5));
  const io::Sequence seq = io::Sequence::open(dir.path().string());
  for (size_t k : {size_t{0}, seq.size() / 2}) {
    const io::CloudData kf = seq.scan(k);
    ASSERT_GT(kf.points.size(), 1000u);
    ASSERT_EQ(kf.labels.size(), kf.points.size());
    // Downsampled at 0.2 m: the same grid keeps every point (one centroid per voxel).
    VoxelGridConfig leaf;
    leaf.leaf_m = 0.2f;
    leaf.min_points_per_voxel = 1;
    EXPECT_EQ(voxel_filter(kf.points, leaf).size(), kf.points.size());
    const double spacing = median_spacing(kf.points);
    EXPECT_GT(spacing, 0.08) << "keyframe " << k;
    EXPECT_LT(spacing, 0.3) << "keyframe " << k;
    // Points are in the keyframe's sensor frame: put into the world (the first keyframe's
    // frame, 1 m above the ground) with the keyframe pose, the ground lies at z = -1. Voxels
    // the ground shares with a pole's foot sit a little higher.
    std::vector<double> dz;
    for (size_t i = 0; i < kf.points.size(); ++i)
      if (kf.labels[i] == kGround)
        dz.push_back(std::fabs((seq.poses()[k] * kf.points[i].xyz().cast<double>()).z() + 1.0));
    ASSERT_GT(dz.size(), kf.points.size() / 4);
    std::sort(dz.begin(), dz.end());
    EXPECT_LT(dz[dz.size() / 2], 0.02) << "keyframe " << k;
    EXPECT_LT(dz.back(), 0.2) << "keyframe " << k;
  }
}

TEST(Keyframes, IntegratingFramesAddsPoints) {
  TempDir one("segmatch_keyframes_test_"), five("segmatch_keyframes_test_");
  export_walk(one.path(), every(3.0, 1));
  export_walk(five.path(), every(3.0, 5));
  const io::Sequence a = io::Sequence::open(one.path().string()), b = io::Sequence::open(five.path().string());
  ASSERT_GE(std::min(a.size(), b.size()), 8u);
  // Along the same street, 0.5 s of rosette fills many more voxels than 0.1 s.
  auto mean_points = [](const io::Sequence& s) {
    size_t n = 0;
    for (size_t k = 0; k < s.size(); ++k) n += s.scan(k).points.size();
    return double(n) / double(s.size());
  };
  EXPECT_GT(mean_points(b), 1.5 * mean_points(a));
}

// The default odometry drifts like a LiDAR-inertial one (KeyframeConfig): over 100 m of a
// straight drive, 0.3-1 deg of heading and 0.5-2 m of position on average over seeds; the same
// seed gives the same poses, another seed others; roll and pitch stay level (gravity).
TEST(Keyframes, DefaultOdometryWandersLikeLidarInertialOdometry) {
  Poses line;
  for (int i = 0; i <= 100; ++i) line.push_back(Pose3d(Eigen::Translation3d(double(i), 0, 0)));
  KeyframeConfig c;
  double heading_deg = 0.0, position_m = 0.0;
  constexpr int kSeeds = 200;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    c.odom_seed = static_cast<uint64_t>(seed);
    const Pose3d end = drifted_odometry(line, c).back();
    heading_deg += std::abs(std::atan2(end.linear()(1, 0), end.linear()(0, 0))) * 180.0 / M_PI / kSeeds;
    position_m += (end.translation() - line.back().translation()).norm() / kSeeds;
    EXPECT_NEAR(end.linear()(2, 2), 1.0, 1e-12) << "roll and pitch stay level";
  }
  EXPECT_GE(heading_deg, 0.3);
  EXPECT_LE(heading_deg, 1.0);
  EXPECT_GE(position_m, 0.5);
  EXPECT_LE(position_m, 2.0);
  c.odom_seed = 7;
  const Poses a = drifted_odometry(line, c), b = drifted_odometry(line, c);
  c.odom_seed = 8;
  const Poses other = drifted_odometry(line, c);
  EXPECT_TRUE(a.back().isApprox(b.back(), 1e-15));
  EXPECT_FALSE(a.back().isApprox(other.back(), 1e-9));
}

TEST(Keyframes, OdometryDriftIsSystematicAndCanBeOff) {
  Poses line;
  for (int i = 0; i <= 10; ++i) line.push_back(Pose3d(Eigen::Translation3d(double(i), 0, 0)));
  KeyframeConfig c;
  c.odom_heading_walk_deg_per_sqrt_m = c.odom_pitch_walk_deg_per_sqrt_m = 0;
  c.odom_scale_error = 0.01;
  c.odom_yaw_drift_deg_per_m = 0.0;
  EXPECT_NEAR(drifted_odometry(line, c).back().translation().x(), 10.1, 1e-9);
  c.odom_scale_error = 0.0;
  c.odom_yaw_drift_deg_per_m = 0.1;
  const Pose3d end = drifted_odometry(line, c).back();
  EXPECT_NEAR(std::atan2(end.linear()(1, 0), end.linear()(0, 0)) * 180.0 / M_PI, 1.0, 1e-9);
  EXPECT_GT(end.translation().y(), 0.0) << "turns left";
  c.odom_yaw_drift_deg_per_m = 0.0;
  const Poses same = drifted_odometry(line, c);
  for (size_t i = 0; i < line.size(); ++i) EXPECT_TRUE(same[i].isApprox(line[i], 1e-12));
}

TEST(Keyframes, SameInputSameBytes) {
  TempDir a("segmatch_keyframes_test_"), b("segmatch_keyframes_test_");
  export_walk(a.path(), every(4.0, 3));
  export_walk(b.path(), every(4.0, 3));
  for (const char* f : {"scans/000000.pcd", "scans/000003.pcd", "poses.txt", "odom_poses.txt", "times.txt"})
    EXPECT_EQ(read_all(a.path() / f), read_all(b.path() / f)) << f;
}

TEST(Keyframes, InvalidConfigurationsAreRefused) {
  KeyframeConfig c;
  c.every_m = -1;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = KeyframeConfig{};
  c.leaf_m = 0.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = KeyframeConfig{};
  c.frames = -2;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  EXPECT_EQ(default_keyframe_frames(livox_avia()), 5);
  EXPECT_EQ(default_keyframe_frames(vlp16()), 1);
}

// generate_dataset with the handheld Livox: keyframes of both traversals next to the KITTI
// layout, their ground truth in the shared world frame, the same bytes on 1 and 2 threads.
TEST(Keyframes, DatasetExportsBothTraversals) {
  TempDir a("segmatch_keyframes_test_"), b("segmatch_keyframes_test_");
  DatasetConfig c = dataset_preset("tiny", 4);
  c.use_sensor("livox-avia");
  EXPECT_DOUBLE_EQ(c.drive_first.sensor_height_m, 1.0);
  c.first_length_m = c.second_length_m = 60;
  c.write_images = false;
  c.keyframes.every_m = 2.0;
  c.threads = 1;
  const DatasetSummary s = generate_dataset(c, a.path().string());
  for (int k = 0; k < 2; ++k) {
    const std::string nn = k == 0 ? "00" : "01";
    const io::Sequence seq = io::Sequence::open((a.path() / "keyframes" / nn).string());
    ASSERT_EQ(seq.size(), s.keyframes[k]);
    ASSERT_GE(seq.size(), 10u);  // every 2 m over 27 and 38 m
    const Poses world = io::read_kitti_poses((a.path() / "ground_truth" / ("keyframe_poses_" + nn + ".txt")).string());
    const Poses scans = io::read_kitti_poses((a.path() / "ground_truth" / ("lidar_poses_" + nn + ".txt")).string());
    std::ifstream frames(a.path() / "ground_truth" / ("keyframe_frames_" + nn + ".txt"));
    ASSERT_EQ(world.size(), seq.size());
    for (size_t i = 0; i < seq.size(); ++i) {
      size_t f = 0;
      ASSERT_TRUE(frames >> f);
      EXPECT_TRUE(world[i].isApprox(scans[f], 1e-12)) << nn << " keyframe " << i;
      EXPECT_TRUE(seq.poses()[i].isApprox(world[0].inverse() * world[i], 1e-9)) << nn << " keyframe " << i;
    }
  }
  c.threads = 2;
  generate_dataset(c, b.path().string());
  for (const char* f : {"keyframes/00/scans/000003.pcd", "keyframes/01/odom_poses.txt", "dataset.json"})
    EXPECT_EQ(read_all(a.path() / f), read_all(b.path() / f)) << f;
}

TEST(SimCli, LivoxKeyframesFromTheCommandLine) {
  const std::string bin = std::string(SEGMATCH_BIN_DIR) + "/segmatch-sim";
  if (!fs::exists(bin)) GTEST_SKIP() << bin << " not built";
  TempDir dir("segmatch_keyframes_test_");
  const auto r = test::run_command(bin +
                                   " --preset tiny --sensor livox-avia --speed-mps 1.5 --length-00-m 50 "
                                   "--length-01-m 50 --keyframes-every-m 2 --keyframe-leaf-m 0.25 "
                                   "--keyframe-frames 3 --odom-drift-pct 0 --odom-yaw-drift-deg-per-m 0 "
                                   "--odom-heading-walk 0 --odom-pitch-walk 0 "
                                   "--no-images --out " +
                                   dir.path().string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("keyframes:"), std::string::npos) << r.output;
  // The tiny world's routes are shorter than asked (39 and 23 m driven here).
  const io::Sequence seq = io::Sequence::open((dir.path() / "keyframes/00").string());
  ASSERT_GE(seq.size(), 12u);
  EXPECT_EQ(read_all(dir.path() / "keyframes/00/poses.txt"), read_all(dir.path() / "keyframes/00/odom_poses.txt"))
      << "no drift asked for";
  // Walking at 1.5 m/s, 2 m take over 1.3 s (at the default 10 m/s: 0.2 s).
  EXPECT_GT(seq.times()[1] - seq.times()[0], 1.3);
  EXPECT_NE(
      test::run_command(bin + " --sensor livox-avia --keyframes-every-m -1 --out " + (dir.path() / "x").string()).code,
      0);
  EXPECT_FALSE(fs::exists(dir.path() / "x"));
}

}  // namespace
}  // namespace segmatch::sim
