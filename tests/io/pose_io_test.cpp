// KITTI poses / calib / times, TUM trajectories, and the camera <-> LiDAR frame change.
#include <segmatch/io/pose_io.h>

#include <cmath>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::ThrowsIoError;

Poses random_poses(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> offset(-2000.0, 2000.0);
  Poses poses;
  for (size_t i = 0; i < n; ++i) {
    Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
    Pose3d pose = Pose3d::Identity();
    pose.linear() = q.normalized().toRotationMatrix();
    pose.translation() = Eigen::Vector3d(offset(rng), offset(rng), offset(rng) / 100.0);
    poses.push_back(pose);
  }
  return poses;
}

// KITTI odometry sequence 00's velodyne-to-camera calibration.
Pose3d kitti00_T_cam0_velo() {
  Eigen::Matrix<double, 3, 4, Eigen::RowMajor> m;
  m << 4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02, -7.210626507497e-03,
      8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02, 9.999738645903e-01, 4.859485810390e-04,
      -7.206933692422e-03, -2.921968648686e-01;
  Pose3d T = Pose3d::Identity();
  T.matrix().topRows<3>() = m;
  return T;
}

double max_difference(const Pose3d& a, const Pose3d& b) { return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff(); }

TEST(KittiPoses, RoundTripIsExact) {
  test::TempDir dir;
  const Poses poses = random_poses(50, 41);
  write_kitti_poses(dir.file("poses.txt"), poses);
  const Poses back = read_kitti_poses(dir.file("poses.txt"));
  ASSERT_EQ(back.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) EXPECT_LT(max_difference(back[i], poses[i]), 1e-9) << i;
}

TEST(KittiPoses, RoundedRotationsAreReorthonormalised) {
  test::TempDir dir;
  // Riverside02's second pose as SLAM tools print it (6 significant digits), plus blank lines
  // at the end and CRLF.
  test::write_bytes(dir.file("poses.txt"),
                    "1 0 0 0 0 1 0 0 0 0 1 0\r\n"
                    "0.999903 -0.0116068 -0.00770509 -1.9494 0.0115921 0.999931 -0.00195905 -0.0144169 "
                    "0.0077273 0.00186954 0.999968 0.0611163\r\n\r\n\n");
  const Poses poses = read_kitti_poses(dir.file("poses.txt"));
  ASSERT_EQ(poses.size(), 2u);
  const Eigen::Matrix3d R = poses[1].linear();
  EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(R(0, 1), -0.0116068, 1e-5);
  EXPECT_EQ(poses[1].translation().x(), -1.9494);
  EXPECT_EQ(poses[1].translation().z(), 0.0611163);
}

TEST(KittiPoses, ErrorsNameTheLine) {
  test::TempDir dir;
  const std::string good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
  struct Case {
    std::string content, expected;
  };
  const std::vector<Case> cases = {
      {good + good + good + good + good + good + "1 0 0 0 0 1 0 0 0 0 1\n",
       "poses.txt line 7: expected 12 numbers, got 11"},
      {good + "1 0 0 0 0 1 0 nan 0 0 1 0\n", "poses.txt line 2: non-finite value 'nan'"},
      {"1 0 0 0 0 1 0 0 0 0 1 inf\n", "line 1: non-finite"},
      {"2 0 0 0 0 1 0 0 0 0 1 0\n", "line 1: rotation is not orthonormal"},
      {"0 1 0 0 1 0 0 0 0 0 1 0\n", "line 1: rotation is a reflection"},
      {good + "1 0 0 0 0 1 0 x 0 0 1 0\n", "line 2: 'x' is not a number"},
      {good + "\n" + good, "line 2: blank line before the last pose"},
  };
  for (const Case& c : cases) {
    test::write_bytes(dir.file("poses.txt"), c.content);
    EXPECT_TRUE(ThrowsIoError([&] { read_kitti_poses(dir.file("poses.txt")); }, {c.expected}));
  }
}

TEST(KittiCalib, RoundTripAndKittiLayout) {
  test::TempDir dir;
  write_kitti_calib(dir.file("calib.txt"), {kitti00_T_cam0_velo()});
  const std::string text = test::read_bytes(dir.file("calib.txt"));
  EXPECT_EQ(text.rfind("P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 ", 0), 0u);
  EXPECT_NE(text.find("\nP3: "), std::string::npos);
  EXPECT_NE(text.find("\nTr: 4.276802385584e-04 -9.999672484946e-01 "), std::string::npos);
  const KittiCalib calib = read_kitti_calib(dir.file("calib.txt"));
  // The file keeps 13 significant digits; reading re-orthonormalises KITTI's 1e-7 errors.
  EXPECT_LT(max_difference(calib.T_cam0_velo, kitti00_T_cam0_velo()), 1e-6);
  EXPECT_LT(max_difference(calib.T_cam0_velo, read_kitti_calib(dir.file("calib.txt")).T_cam0_velo), 1e-15);
}

TEST(KittiCalib, ObjectStyleKeyAndErrors) {
  test::TempDir dir;
  test::write_bytes(dir.file("calib.txt"),
                    "P2: 1 0 0 0 0 1 0 0 0 0 1 0\nTr_velo_to_cam: 0 -1 0 0.5 0 0 -1 0 1 0 0 0\n");
  const Pose3d T = read_kitti_calib(dir.file("calib.txt")).T_cam0_velo;
  EXPECT_EQ(T.translation().x(), 0.5);
  EXPECT_NEAR(T.linear()(2, 0), 1.0, 1e-15);
  test::write_bytes(dir.file("calib.txt"), "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_kitti_calib(dir.file("calib.txt")); }, {"calib.txt", "no 'Tr:'"}));
  test::write_bytes(dir.file("calib.txt"), "P0: 1\nTr: 1 0 0 0 0 1 0 0 0 0 1\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_kitti_calib(dir.file("calib.txt")); },
                            {"calib.txt line 2", "expected 12 numbers, got 11"}));
}

// KITTI's axes: camera x right, y down, z forward; velodyne x forward, y left, z up.
Pose3d axis_permutation_T_cam0_velo() {
  Pose3d T = Pose3d::Identity();
  T.linear() << 0, -1, 0,  //
      0, 0, -1,            //
      1, 0, 0;
  T.translation() = Eigen::Vector3d(0.1, -0.2, 0.3);
  return T;
}

TEST(FrameChange, ForwardMotionOfTheCameraIsForwardMotionOfTheLidar) {
  Pose3d T_cam0_cam1 = Pose3d::Identity();
  T_cam0_cam1.translation() = Eigen::Vector3d(0, 0, 5);  // 5 m along camera z (forward)
  const Poses lidar = camera_to_lidar_poses({T_cam0_cam1}, axis_permutation_T_cam0_velo());
  // Tr^-1 P Tr = R^T (R x + t + d - t) = x + R^T d with R^T (0,0,5) = (5,0,0).
  EXPECT_LT((lidar[0].translation() - Eigen::Vector3d(5, 0, 0)).norm(), 1e-12);
  EXPECT_LT((lidar[0].linear() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
}

TEST(FrameChange, YawAboutCameraYIsYawAboutMinusLidarZ) {
  const double angle = 0.3;
  Pose3d T_cam0_cam1 = Pose3d::Identity();
  T_cam0_cam1.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Poses lidar = camera_to_lidar_poses({T_cam0_cam1}, axis_permutation_T_cam0_velo());
  // Camera y is velodyne -z, so the same turn is a rotation by -angle about velodyne z...
  const Eigen::Matrix3d expected_R = Eigen::AngleAxisd(-angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_LT((lidar[0].linear() - expected_R).norm(), 1e-12);
  // ...and the lever arm moves the LiDAR: R^T (R_y t - t) with t = (0.1, -0.2, 0.3).
  const Eigen::Vector3d t(0.1, -0.2, 0.3);
  const Eigen::Matrix3d R = axis_permutation_T_cam0_velo().linear();
  const Eigen::Vector3d expected_t = R.transpose() * (T_cam0_cam1.linear() * t - t);
  EXPECT_LT((lidar[0].translation() - expected_t).norm(), 1e-12);
  EXPECT_GT(expected_t.norm(), 0.05);  // the lever arm matters in this test
}

TEST(FrameChange, CameraLidarCameraRoundTripThroughFiles) {
  test::TempDir dir;
  const Poses camera = random_poses(30, 42);
  write_kitti_poses(dir.file("poses.txt"), camera);
  write_kitti_calib(dir.file("calib.txt"), {kitti00_T_cam0_velo()});
  const Pose3d Tr = read_kitti_calib(dir.file("calib.txt")).T_cam0_velo;
  const Poses lidar = camera_to_lidar_poses(read_kitti_poses(dir.file("poses.txt")), Tr);
  const Poses again = lidar_to_camera_poses(lidar, Tr);
  ASSERT_EQ(again.size(), camera.size());
  for (size_t i = 0; i < camera.size(); ++i) {
    EXPECT_LT(max_difference(again[i], camera[i]), 1e-9) << i;
    // The frame change is a real change: the LiDAR trajectory differs from the camera one.
    EXPECT_GT(max_difference(lidar[i], camera[i]), 1e-3) << i;
  }
}

TEST(Tum, RoundTrip) {
  test::TempDir dir;
  StampedPoses poses;
  poses.poses = random_poses(20, 43);
  for (size_t i = 0; i < 20; ++i) poses.times.push_back(1565943695.2280283 + 0.1 * double(i));
  write_tum(dir.file("traj.tum"), poses);
  const StampedPoses back = read_tum(dir.file("traj.tum"));
  ASSERT_EQ(back.poses.size(), 20u);
  EXPECT_EQ(back.times, poses.times);
  for (size_t i = 0; i < 20; ++i) EXPECT_LT(max_difference(back.poses[i], poses.poses[i]), 1e-9) << i;
}

TEST(Tum, CommentsAndUnnormalisedQuaternions) {
  test::TempDir dir;
  // qw last; (0, 0, 2, 2) normalises to a 90 degree turn about z.
  test::write_bytes(dir.file("t.txt"), "# timestamp tx ty tz qx qy qz qw\n\n10.5 1 2 3 0 0 2 2\n  # done\n");
  const StampedPoses poses = read_tum(dir.file("t.txt"));
  ASSERT_EQ(poses.poses.size(), 1u);
  EXPECT_EQ(poses.times[0], 10.5);
  EXPECT_EQ(poses.poses[0].translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_LT((poses.poses[0].linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 1e-12);
}

TEST(Tum, Errors) {
  test::TempDir dir;
  test::write_bytes(dir.file("t.txt"), "# c\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_tum(dir.file("t.txt")); }, {"t.txt line 3", "zero norm"}));
  test::write_bytes(dir.file("t.txt"), "1 0 0 0 0 0 1\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_tum(dir.file("t.txt")); }, {"t.txt line 1", "expected 8 numbers, got 7"}));
  StampedPoses mismatched;
  mismatched.times = {1.0};
  EXPECT_TRUE(ThrowsIoError([&] { write_tum(dir.file("w.txt"), mismatched); }, {"w.txt", "1 times for 0 poses"}));
}

TEST(Times, RoundTripAndErrors) {
  test::TempDir dir;
  const std::vector<double> times = {0.0, 0.103760, 1565943695.2280283, 1e-7};
  write_times(dir.file("times.txt"), times);
  EXPECT_EQ(read_times(dir.file("times.txt")), times);
  test::write_bytes(dir.file("times.txt"), "0.0\n0.1 0.2\n");
  EXPECT_TRUE(
      ThrowsIoError([&] { read_times(dir.file("times.txt")); }, {"times.txt line 2", "expected 1 number, got 2"}));
  test::write_bytes(dir.file("times.txt"), "0.0\n-nan\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_times(dir.file("times.txt")); }, {"times.txt line 2", "non-finite"}));
}

// --odometry / --truth take either format: told apart by the first pose line's columns.
TEST(AnyPoses, KittiAndTumAreToldApartByTheirColumns) {
  test::TempDir dir;
  const Poses poses = random_poses(20, 43);
  write_kitti_poses(dir.file("poses.txt"), poses);
  StampedPoses stamped;
  for (size_t i = 0; i < poses.size(); ++i) stamped.times.push_back(0.1 * static_cast<double>(i));
  stamped.poses = poses;
  write_tum(dir.file("poses.tum"), stamped);
  const Poses from_kitti = read_poses(dir.file("poses.txt")), from_tum = read_poses(dir.file("poses.tum"));
  ASSERT_EQ(from_kitti.size(), poses.size());
  ASSERT_EQ(from_tum.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_LT(max_difference(from_kitti[i], poses[i]), 1e-12);
    EXPECT_LT(max_difference(from_tum[i], poses[i]), 1e-9);
  }
  test::write_bytes(dir.file("bad.txt"), "# a comment\n1 2 3 4 5 6 7\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_poses(dir.file("bad.txt")); }, {"bad.txt", "7 columns", "12 (KITTI", "8 (TUM"}));
  test::write_bytes(dir.file("empty.txt"), "\n# nothing\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_poses(dir.file("empty.txt")); }, {"empty.txt", "no poses"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
