// Which poses build a replayed query's local cloud (io/replay.h): the vehicle's odometry, found
// or refused by name.
#include <segmatch/io/replay.h>

#include <fstream>
#include <stdexcept>

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

}  // namespace
}  // namespace io
}  // namespace segmatch
