// A ROS 2 bag as a Sequence (io/sequence.h, BagOptions): each cloud's pose interpolated at its
// stamp, clouds outside the poses' span skipped and counted, poses from /tf, the topic chosen or
// refused by name, and a ring field measured by the profile.
#include <segmatch/io/auto_profile.h>
#include <segmatch/io/sequence.h>

#include <gtest/gtest.h>

#include <cmath>

#include "bag_test_util.h"

namespace segmatch {
namespace io {
namespace {

RosHeader stamp(double t_s, const std::string& frame) {
  RosHeader h;
  h.stamp_sec = static_cast<int32_t>(std::floor(t_s));
  h.stamp_nanosec = static_cast<uint32_t>(std::llround((t_s - std::floor(t_s)) * 1e9));
  h.frame_id = frame;
  return h;
}

StampedPose pose_at(double t_s, double x_m, double yaw_rad) {
  StampedPose p;
  p.header = stamp(t_s, "map");
  p.child_frame_id = "lidar";
  p.T_parent_child = Pose3d::Identity();
  p.T_parent_child.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  p.T_parent_child.translation() = Eigen::Vector3d(x_m, 0.0, 0.0);
  return p;
}

PointCloud three_points() { return {Point{1.f, 2.f, 3.f, 4.f}, Point{5.f, 6.f, 7.f, 8.f}, Point{-1.f, 0.f, 2.f, 0.f}}; }

// Clouds at t = 0.5, 1.5, 2.5, 3.5 and 9 s; odometry at t = 1, 2, 3, 4 s, x = t metres, yaw 0.1 t.
std::string write_drive(const test::TempDir& dir, bool with_tf) {
  const std::string path = dir.file("drive.mcap");
  McapWriter bag(path);
  const uint16_t points = bag.add_channel("/points", "sensor_msgs/msg/PointCloud2");
  const uint16_t odom = bag.add_channel("/odom", "nav_msgs/msg/Odometry");
  const uint16_t tf = bag.add_channel("/tf", "tf2_msgs/msg/TFMessage");
  for (double t : {0.5, 1.5, 2.5, 3.5, 9.0})
    bag.write(points, static_cast<uint64_t>(t * 1e9), encode_point_cloud2(stamp(t, "lidar"), three_points()));
  for (double t : {1.0, 2.0, 3.0, 4.0}) {
    bag.write(odom, static_cast<uint64_t>(t * 1e9), encode_odometry(pose_at(t, t, 0.1 * t)));
    if (with_tf) bag.write(tf, static_cast<uint64_t>(t * 1e9), encode_tf_message({pose_at(t, 2.0 * t, 0.0)}));
  }
  bag.close();
  return path;
}

TEST(BagSequence, PosesInterpolatedAtEachCloudsStampAndCloudsOutsideSkipped) {
  test::TempDir dir;
  const Sequence seq = Sequence::open(write_drive(dir, false));
  EXPECT_EQ(seq.layout(), SequenceLayout::kBag);
  ASSERT_EQ(seq.size(), 3u) << "0.5 s and 9 s lie outside the odometry's 1..4 s";
  EXPECT_NE(seq.source_note().find("2 clouds outside the poses' time span skipped"), std::string::npos)
      << seq.source_note();
  EXPECT_NE(seq.source_note().find("/odom"), std::string::npos) << seq.source_note();
  for (size_t i = 0; i < 3; ++i) {
    const double t = 1.5 + static_cast<double>(i);
    EXPECT_NEAR(seq.times()[i], t, 1e-6);
    EXPECT_NEAR(seq.poses()[i].translation().x(), t, 1e-9);
    EXPECT_NEAR(Eigen::AngleAxisd(seq.poses()[i].linear()).angle(), 0.1 * t, 1e-9) << "slerp halfway";
  }
  const CloudData scan = seq.scan(1);
  ASSERT_EQ(scan.points.size(), 3u);
  EXPECT_FLOAT_EQ(scan.points[1].y, 6.f);
  EXPECT_THROW(seq.scan(3), std::out_of_range);
}

TEST(BagSequence, PosesFromTfWhenAMapFrameIsGiven) {
  test::TempDir dir;
  SequenceOptions o;
  o.bag.map_frame = "map";
  const Sequence seq = Sequence::open(write_drive(dir, true), o);
  ASSERT_EQ(seq.size(), 3u);
  EXPECT_NEAR(seq.poses()[0].translation().x(), 3.0, 1e-9) << "/tf says x = 2 t";
  EXPECT_NE(seq.source_note().find("/tf"), std::string::npos) << seq.source_note();
  o.bag.map_frame = "elsewhere";
  EXPECT_THROW(Sequence::open(dir.file("drive.mcap"), o), IoError) << "a frame /tf does not connect";
}

TEST(BagSequence, TopicsAreChosenOrRefusedByName) {
  test::TempDir dir;
  const std::string path = write_drive(dir, true);
  SequenceOptions o;
  o.bag.points_topic = "/velodyne";
  try {
    Sequence::open(path, o);
    FAIL() << "a missing topic must be refused";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("no topic /velodyne"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("/points (sensor_msgs/msg/PointCloud2)"), std::string::npos) << e.what();
  }
  o.bag.points_topic = "/odom";
  EXPECT_THROW(Sequence::open(path, o), IoError) << "not a PointCloud2";
  SequenceOptions folder;
  folder.bag.pose_topic = "/odom";
  EXPECT_THROW(Sequence::open(dir.path(), folder), IoError) << "bag options on a folder";
}

// 16 rings 2 degrees apart, each point's elevation jittered by up to 0.9 degrees: the histogram
// cannot separate them; the ring field does.
TEST(BagSequence, TheProfileCountsRingsFromARingField) {
  test::TempDir dir;
  test::Cloud2 c;
  c.fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"ring", 12, 4}};
  c.point_step = 16;
  for (int ring = 0; ring < 16; ++ring)
    for (int a = 0; a < 360; ++a) {
      const double jitter = 0.9 * std::sin(12.9898 * (ring * 360 + a));
      const double e = (-15.0 + 2.0 * ring + jitter) * M_PI / 180.0, az = a * M_PI / 180.0, r = 10.0 + (a % 7);
      test::PointRecord p(16, false);
      p.set<float>(0, static_cast<float>(r * std::cos(e) * std::cos(az)))
          .set<float>(4, static_cast<float>(r * std::cos(e) * std::sin(az)))
          .set<float>(8, static_cast<float>(r * std::sin(e)))
          .set<uint16_t>(12, static_cast<uint16_t>(ring));
      c.data += p.bytes;
    }
  c.width = 16 * 360;
  c.row_step = c.width * c.point_step;
  const std::string path = dir.file("rings.mcap");
  {
    McapWriter bag(path);
    const uint16_t points = bag.add_channel("/points", "sensor_msgs/msg/PointCloud2");
    const uint16_t odom = bag.add_channel("/odom", "nav_msgs/msg/Odometry");
    bag.write(points, 1700000000250000000ull, c.cdr());  // Cloud2's stamp: 1700000000.25 s
    bag.write(odom, 1700000000000000000ull, encode_odometry(pose_at(1700000000.0, 0.0, 0.0)));
    bag.write(odom, 1700000001000000000ull, encode_odometry(pose_at(1700000001.0, 1.0, 0.0)));
  }
  const Sequence seq = Sequence::open(path);
  ASSERT_EQ(seq.size(), 1u);
  EXPECT_EQ(seq.scan(0).rings.size(), 16u * 360u);
  const InputMeasurements m = measure_sequence(seq, 0, 0, 1);
  EXPECT_EQ(m.ring_count, 16.0);
  EXPECT_NEAR(m.ring_spacing_deg, 2.0, 0.2);
}

}  // namespace
}  // namespace io
}  // namespace segmatch
