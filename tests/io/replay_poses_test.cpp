// Which poses build a replayed query's local cloud (io/replay.h): the vehicle's odometry, found
// or refused by name; and the cold-start replay of single scans.
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/pose_io.h>
#include <segmatch/io/replay.h>
#include <segmatch/io/sequence.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <vector>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::ThrowsIoError;

TEST(ReplayPoses, OdometryIsTheExplicitFileElseTheSequencesOwnElseRefused) {
  test::TempDir dir;
  EXPECT_TRUE(ThrowsIoError([&] { odometry_poses_path(dir.path(), ""); },
                            {"no odom_poses.txt", "--odometry FILE", "--cloud-poses reference"}));
  std::ofstream(dir.file("odom_poses.txt")) << "1 0 0 0 0 1 0 0 0 0 1 0\n";
  EXPECT_EQ(odometry_poses_path(dir.path(), ""), dir.file("odom_poses.txt"));
  std::ofstream(dir.file("lio.txt")) << "1 0 0 0 0 1 0 0 0 0 1 0\n";
  EXPECT_EQ(odometry_poses_path(dir.path(), dir.file("lio.txt")), dir.file("lio.txt"));
  EXPECT_TRUE(ThrowsIoError([&] { odometry_poses_path(dir.path(), dir.file("missing.txt")); },
                            {"missing.txt", "odometry poses file not found"}));
}

TEST(ReplayPoses, CloudPosesParseByName) {
  EXPECT_EQ(parse_cloud_poses("odometry"), CloudPoses::kOdometry);
  EXPECT_EQ(parse_cloud_poses("reference"), CloudPoses::kReference);
  EXPECT_STREQ(to_string(CloudPoses::kReference), "reference");
  EXPECT_THROW(parse_cloud_poses("truth"), std::invalid_argument);
}

// Single-scan replay: a query at every scan from the first (no warm-up), whose cloud is that
// scan alone in the odometry frame (the first used scan's frame), raw, and whose newest scans are
// the same scan thinned; an accumulating replay of the same folder holds more than one scan.
TEST(ReplaySingleScan, EveryQueryIsOneScanInTheOdometryFrame) {
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("scans"));
  Poses poses;
  std::vector<PointCloud> scans;
  for (size_t i = 0; i < 6; ++i) {
    Pose3d T = Pose3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.1 * double(i), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(3.0 * double(i), 0.5, 0.0);
    poses.push_back(T);
    scans.push_back(test::random_cloud(200, static_cast<uint32_t>(7 + i)));
    char name[32];
    std::snprintf(name, sizeof(name), "scans/%06zu.pcd", i);
    write_pcd(dir.file(name), scans.back());
  }
  write_kitti_poses(dir.file("poses.txt"), poses);
  const Sequence seq = Sequence::open(dir.path());
  ReplayConfig config;
  config.first = 1;
  config.every_m = 5.0;
  config.single_scan = true;
  std::vector<ReplayQuery> queries;
  replay_sequence(seq, config, [&](const ReplayQuery& q) { return queries.push_back(q), true; });
  ASSERT_EQ(queries.size(), 3u) << "scans 1, 3 and 5: one every 5 m from the first, no warm-up";
  for (const ReplayQuery& q : queries) {
    const Pose3d T_odom_sensor = poses[1].inverse() * poses[q.frame];
    EXPECT_TRUE(q.T_odom_sensor.isApprox(T_odom_sensor, 1e-9)) << q.frame;
    EXPECT_FALSE(q.voxelized);
    const PointCloud& scan = seq.scan(q.frame).points;
    ASSERT_EQ(q.cloud_odom.size(), scan.size()) << q.frame;
    for (size_t k = 0; k < scan.size(); ++k) {
      const Eigen::Vector3d expected = T_odom_sensor * Eigen::Vector3d(scan[k].x, scan[k].y, scan[k].z);
      EXPECT_LT((Eigen::Vector3d(q.cloud_odom[k].x, q.cloud_odom[k].y, q.cloud_odom[k].z) - expected).norm(), 1e-4);
    }
    EXPECT_FALSE(q.newest_odom.empty());
    EXPECT_LE(q.newest_odom.size(), scan.size());
  }
  config.newest_m = 0.0;
  queries.clear();
  replay_sequence(seq, config, [&](const ReplayQuery& q) { return queries.push_back(q), true; });
  ASSERT_FALSE(queries.empty());
  EXPECT_TRUE(queries.front().newest_odom.empty()) << "newest_m 0: none";
  config.single_scan = false;
  config.warmup_m = 0.0;
  config.voxelize = false;
  queries.clear();
  replay_sequence(seq, config, [&](const ReplayQuery& q) { return queries.push_back(q), true; });
  ASSERT_GE(queries.size(), 2u);
  EXPECT_GT(queries[1].cloud_odom.size(), seq.scan(queries[1].frame).points.size()) << "accumulated";
}

}  // namespace
}  // namespace io
}  // namespace segmatch
