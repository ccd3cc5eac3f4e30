// Sequence on generated KITTI and PCD-keyframe folders, and its consistency checks.
#include <segmatch/io/pose_io.h>
#include <segmatch/io/sequence.h>

#include <cstdio>
#include <filesystem>
#include <limits>
#include <stdexcept>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::ThrowsIoError;

std::string scan_name(size_t i, const char* ext) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06zu%s", i, ext);
  return name;
}

Pose3d calib_T_cam0_velo() {
  Pose3d T = Pose3d::Identity();
  T.linear() << 0, -1, 0, 0, 0, -1, 1, 0, 0;
  T.translation() = Eigen::Vector3d(-0.01, -0.05, -0.29);
  return T;
}

// LiDAR poses: driving along x with a slow left turn.
Poses lidar_trajectory(size_t n) {
  Poses poses;
  for (size_t i = 0; i < n; ++i) {
    Pose3d T = Pose3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.05 * double(i), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(2.0 * double(i), 0.1 * double(i * i), 0.0);
    poses.push_back(T);
  }
  return poses;
}

// A KITTI-layout folder with n scans (scan i has 100 + 10 i points), camera-frame poses,
// calib.txt, times.txt and SemanticKITTI labels. Files are created in reverse order so that
// directory order is not name order.
struct KittiFolder {
  test::TempDir dir;
  size_t n;
  std::vector<PointCloud> clouds;
  std::vector<std::vector<uint32_t>> labels;

  explicit KittiFolder(size_t count) : n(count) {
    for (size_t k = n; k > 0; --k) {
      const size_t i = k - 1;
      clouds.insert(clouds.begin(), test::random_cloud(100 + 10 * i, static_cast<uint32_t>(50 + i)));
      labels.insert(labels.begin(), test::random_labels(100 + 10 * i, static_cast<uint32_t>(60 + i)));
    }
    std::filesystem::create_directories(dir.file("velodyne"));
    std::filesystem::create_directories(dir.file("labels"));
    for (size_t k = n; k > 0; --k) {
      write_kitti_bin(dir.file("velodyne/" + scan_name(k - 1, ".bin")), clouds[k - 1]);
      write_kitti_labels(dir.file("labels/" + scan_name(k - 1, ".label")), labels[k - 1]);
    }
    write_kitti_calib(dir.file("calib.txt"), {calib_T_cam0_velo()});
    write_kitti_poses(dir.file("poses.txt"), lidar_to_camera_poses(lidar_trajectory(n), calib_T_cam0_velo()));
    std::vector<double> times;
    for (size_t i = 0; i < n; ++i) times.push_back(0.1037 * double(i));
    write_times(dir.file("times.txt"), times);
  }
};

TEST(Sequence, KittiLayout) {
  KittiFolder f(5);
  const Sequence seq = Sequence::open(f.dir.path());
  EXPECT_EQ(seq.layout(), SequenceLayout::kKitti);
  ASSERT_EQ(seq.size(), 5u);
  EXPECT_EQ(seq.folder(), f.dir.path());
  EXPECT_TRUE(seq.has_times());
  EXPECT_TRUE(seq.has_labels());
  EXPECT_DOUBLE_EQ(seq.times()[3], 0.1037 * 3);
  const Poses expected = lidar_trajectory(5);
  ASSERT_EQ(seq.poses().size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_LT((seq.poses()[i].matrix() - expected[i].matrix()).cwiseAbs().maxCoeff(), 1e-9) << i;
    EXPECT_EQ(seq.scan_path(i), f.dir.file("velodyne/" + scan_name(i, ".bin")));
  }
  const CloudData scan = seq.scan(2);
  EXPECT_TRUE(test::same_points(scan.points, f.clouds[2]));
  EXPECT_EQ(scan.labels, f.labels[2]);
  EXPECT_THROW(seq.scan(5), std::out_of_range);
  EXPECT_THROW(seq.scan_path(99), std::out_of_range);
}

TEST(Sequence, KittiNonFinitePointsKeepLabelsAligned) {
  KittiFolder f(2);
  PointCloud cloud = f.clouds[1];
  cloud[0].x = std::numeric_limits<float>::quiet_NaN();
  cloud[5].y = std::numeric_limits<float>::infinity();
  write_kitti_bin(f.dir.file("velodyne/000001.bin"), cloud);
  const CloudData scan = Sequence::open(f.dir.path()).scan(1);
  EXPECT_EQ(scan.dropped_non_finite, 2u);
  ASSERT_EQ(scan.labels.size(), scan.points.size());
  EXPECT_EQ(scan.labels[0], f.labels[1][1]);
  EXPECT_EQ(scan.labels[4], f.labels[1][6]);
  EXPECT_EQ(scan.points[4].x, cloud[6].x);
}

TEST(Sequence, KittiWithoutTimesOrLabels) {
  KittiFolder f(4);
  std::filesystem::remove(f.dir.file("times.txt"));
  std::filesystem::remove_all(f.dir.file("labels"));
  const Sequence seq = Sequence::open(f.dir.path());
  EXPECT_FALSE(seq.has_times());
  EXPECT_FALSE(seq.has_labels());
  ASSERT_EQ(seq.times().size(), 4u);
  EXPECT_DOUBLE_EQ(seq.times()[3], 0.3);
  EXPECT_TRUE(seq.scan(3).labels.empty());
}

TEST(Sequence, LidarFrameAndPosesPathOverrides) {
  KittiFolder f(3);
  write_kitti_poses(f.dir.file("lidar_poses.txt"), lidar_trajectory(3));
  std::filesystem::remove(f.dir.file("calib.txt"));  // not needed for LiDAR-frame poses
  SequenceOptions options;
  options.poses_path = f.dir.file("lidar_poses.txt");
  options.pose_frame = PoseFrame::kLidar;
  const Sequence seq = Sequence::open(f.dir.path(), options);
  EXPECT_LT((seq.poses()[2].matrix() - lidar_trajectory(3)[2].matrix()).norm(), 1e-9);
}

TEST(Sequence, MismatchErrors) {
  KittiFolder f(5);
  write_kitti_poses(f.dir.file("poses.txt"), Poses(4, Pose3d::Identity()));
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(f.dir.path()); }, {f.dir.path(), "5 scans but 4 poses in poses.txt"}));
  write_kitti_poses(f.dir.file("poses.txt"), Poses(5, Pose3d::Identity()));
  write_times(f.dir.file("times.txt"), {0, 1, 2, 3, 4, 5});
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(f.dir.path()); }, {"5 scans but 6 times in times.txt"}));
  write_times(f.dir.file("times.txt"), {0, 1, 2, 3, 4});
  std::filesystem::remove(f.dir.file("labels/000004.label"));
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(f.dir.path()); }, {"5 scans but 4 label files in labels/"}));
  write_kitti_labels(f.dir.file("labels/000009.label"), {});
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(f.dir.path()); }, {"000009.label", "does not match scan"}));
  std::filesystem::remove(f.dir.file("labels/000009.label"));
  write_kitti_labels(f.dir.file("labels/000004.label"), {1, 2, 3});
  const Sequence seq = Sequence::open(f.dir.path());  // per-scan counts are checked lazily
  EXPECT_TRUE(ThrowsIoError([&] { seq.scan(4); }, {"000004.label", "has 3 labels but", "000004.bin has 140 points"}));
}

TEST(Sequence, MissingPiecesAreNamed) {
  KittiFolder f(2);
  std::filesystem::remove(f.dir.file("calib.txt"));
  EXPECT_TRUE(ThrowsIoError(
      [&] { Sequence::open(f.dir.path()); },
      {"missing file: " + f.dir.file("calib.txt"), "needed to convert camera-frame poses to the LiDAR frame"}));
  std::filesystem::remove(f.dir.file("poses.txt"));
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(f.dir.path()); }, {"missing file: " + f.dir.file("poses.txt")}));
  EXPECT_TRUE(
      ThrowsIoError([&] { Sequence::open(f.dir.file("nowhere")); }, {"missing folder: " + f.dir.file("nowhere")}));
  test::TempDir empty;
  std::filesystem::create_directories(empty.file("velodyne"));
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(empty.path()); },
                            {empty.path(), "no scans found: expected velodyne/NNNNNN.bin or scans/NNNNNN.pcd"}));
}

TEST(Sequence, TruncatedScanFailsOnRead) {
  KittiFolder f(3);
  std::filesystem::resize_file(f.dir.file("velodyne/000001.bin"), 1001);
  const Sequence seq = Sequence::open(f.dir.path());
  EXPECT_NO_THROW(seq.scan(0));
  EXPECT_TRUE(ThrowsIoError([&] { seq.scan(1); }, {"velodyne/000001.bin", "multiple of 16"}));
}

TEST(Sequence, PcdKeyframes) {
  test::TempDir dir;
  const Poses poses = lidar_trajectory(4);
  std::vector<PointCloud> clouds;
  for (size_t i = 0; i < 4; ++i) {
    clouds.push_back(test::random_cloud(200 + i, static_cast<uint32_t>(70 + i)));
    std::filesystem::create_directories(dir.file("scans"));
    write_pcd(dir.file("scans/" + scan_name(3 - i, ".pcd")), clouds.back());
  }
  write_kitti_poses(dir.file("poses.txt"), poses);
  write_times(dir.file("times.txt"), {5.0, 5.5, 6.0, 6.5});
  const Sequence seq = Sequence::open(dir.path());
  EXPECT_EQ(seq.layout(), SequenceLayout::kPcdKeyframes);
  ASSERT_EQ(seq.size(), 4u);
  EXPECT_FALSE(seq.has_labels());
  EXPECT_EQ(seq.times()[3], 6.5);
  EXPECT_LT((seq.poses()[3].matrix() - poses[3].matrix()).norm(), 1e-9);  // LiDAR frame: as given
  EXPECT_TRUE(test::same_points(seq.scan(0).points, clouds[3]));          // 000000.pcd was written last
  EXPECT_EQ(seq.scan_path(1), dir.file("scans/000001.pcd"));
}

TEST(Sequence, PcdFilesDirectlyInFolderWithLabels) {
  test::TempDir dir;
  for (size_t i = 0; i < 3; ++i) {
    const std::vector<uint32_t> labels(50, static_cast<uint32_t>(i + 1));
    write_pcd(dir.file(scan_name(i, ".pcd")), test::random_cloud(50, 80), PcdEncoding::kBinaryCompressed, &labels);
  }
  write_kitti_poses(dir.file("poses.txt"), lidar_trajectory(3));
  const Sequence seq = Sequence::open(dir.path());
  EXPECT_EQ(seq.layout(), SequenceLayout::kPcdKeyframes);
  EXPECT_TRUE(seq.has_labels());
  EXPECT_EQ(seq.scan(2).labels, std::vector<uint32_t>(50, 3u));
  // Camera-frame poses for PCD keyframes need calib.txt too.
  SequenceOptions camera;
  camera.pose_frame = PoseFrame::kCamera;
  EXPECT_TRUE(ThrowsIoError([&] { Sequence::open(dir.path(), camera); }, {"missing file:", "calib.txt"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
