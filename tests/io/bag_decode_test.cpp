// CDR decoding of the ROS 2 messages a LiDAR drive records, from payloads built by hand (not by
// the library's encoders): PointCloud2 in the layouts drivers publish, Odometry, PoseStamped and
// TFMessage with known values, and the malformed payloads each must refuse.
#include <segmatch/io/bag.h>

#include <cmath>
#include <limits>

#include "bag_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::Cdr;
using test::Cloud2;
using test::PointRecord;
using test::ThrowsIoError;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Fields in a driver's order with padding between them and an unused rgb field: intensity @0,
// (pad), z @8, y @12, x @16, rgb @20, point_step 24.
Cloud2 shuffled_cloud(bool cdr_big_endian, bool data_big_endian) {
  Cloud2 c;
  c.cdr_big_endian = cdr_big_endian;
  c.is_bigendian = data_big_endian;
  c.width = 2;
  c.point_step = 24;
  c.row_step = 48;
  c.fields = {{"intensity", 0, 7}, {"z", 8, 7}, {"y", 12, 7}, {"x", 16, 7}, {"rgb", 20, 7}};
  for (int i = 0; i < 2; ++i) {
    PointRecord r(24, data_big_endian);
    r.set<float>(0, 10.f + i).set<float>(8, 3.f + i).set<float>(12, 2.f + i).set<float>(16, 1.f + i);
    r.set<float>(20, 99.f);
    c.data += r.bytes;
  }
  return c;
}

void expect_shuffled_points(const PointCloud2Message& m) {
  ASSERT_EQ(m.cloud.points.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(m.cloud.points[i].x, 1.f + i);
    EXPECT_EQ(m.cloud.points[i].y, 2.f + i);
    EXPECT_EQ(m.cloud.points[i].z, 3.f + i);
    EXPECT_EQ(m.cloud.points[i].intensity, 10.f + i);
  }
  EXPECT_TRUE(m.cloud.has_intensity);
  EXPECT_TRUE(m.rings.empty());
  EXPECT_EQ(m.header.stamp_sec, 1700000000);
  EXPECT_EQ(m.header.stamp_nanosec, 250000000u);
  EXPECT_EQ(m.header.frame_id, "lidar");
  EXPECT_DOUBLE_EQ(m.header.stamp_s(), 1700000000.25);
}

TEST(BagPointCloud2, AnyFieldOrderWithPaddingAndUnusedFields) {
  expect_shuffled_points(decode_point_cloud2(shuffled_cloud(false, false).cdr()));
}

TEST(BagPointCloud2, BigEndianPointData) {
  expect_shuffled_points(decode_point_cloud2(shuffled_cloud(false, true).cdr()));
}

TEST(BagPointCloud2, BigEndianCdr) {
  expect_shuffled_points(decode_point_cloud2(shuffled_cloud(true, false).cdr()));
  expect_shuffled_points(decode_point_cloud2(shuffled_cloud(true, true).cdr()));
}

TEST(BagPointCloud2, Float64XyzAndUint8IntensityWithoutIntensityField) {
  Cloud2 c;
  c.width = 1;
  c.point_step = 32;
  c.row_step = 32;
  c.fields = {{"x", 0, 8}, {"y", 8, 8}, {"z", 16, 8}, {"intensity", 24, 2}};
  c.data = PointRecord(32, false)
               .set<double>(0, 1e6 + 0.5)
               .set<double>(8, -2.25)
               .set<double>(16, 0.125)
               .set<uint8_t>(24, 200)
               .bytes;
  const PointCloud2Message m = decode_point_cloud2(c.cdr());
  ASSERT_EQ(m.cloud.points.size(), 1u);
  EXPECT_EQ(m.cloud.points[0].x, 1e6f + 0.5f);
  EXPECT_EQ(m.cloud.points[0].y, -2.25f);
  EXPECT_EQ(m.cloud.points[0].z, 0.125f);
  EXPECT_EQ(m.cloud.points[0].intensity, 200.f);

  c.fields.pop_back();  // no intensity
  const PointCloud2Message plain = decode_point_cloud2(c.cdr());
  EXPECT_FALSE(plain.cloud.has_intensity);
  EXPECT_EQ(plain.cloud.points[0].intensity, 0.f);
}

// An organised 2 x 3 cloud with row padding (row_step 40 > 3 * 12), two NaN points, and a
// uint16 ring that must stay with its point when the NaNs are dropped.
TEST(BagPointCloud2, Organised2x3WithNaNsAndUint16Rings) {
  Cloud2 c;
  c.height = 2;
  c.width = 3;
  c.point_step = 14;
  c.row_step = 48;
  c.fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"ring", 12, 4}};
  for (int row = 0; row < 2; ++row) {
    for (int col = 0; col < 3; ++col) {
      const int i = row * 3 + col;
      PointRecord r(14, false);
      r.set<float>(0, (i == 1 || i == 5) ? kNaN : float(i)).set<float>(4, 1.f).set<float>(8, 0.f);
      r.set<uint16_t>(12, static_cast<uint16_t>(100 + i));
      c.data += r.bytes;
    }
    c.data += std::string(48 - 3 * 14, '\x7f');  // row padding: never read
  }
  const PointCloud2Message m = decode_point_cloud2(c.cdr());
  EXPECT_EQ(m.height, 2u);
  EXPECT_EQ(m.width, 3u);
  ASSERT_EQ(m.cloud.points.size(), 4u);
  EXPECT_EQ(m.cloud.dropped_non_finite, 2u);
  EXPECT_EQ(m.rings, (std::vector<uint16_t>{100, 102, 103, 104}));
  EXPECT_EQ(m.cloud.points[1].x, 2.f);
  EXPECT_EQ(m.cloud.points[3].x, 4.f);
  EXPECT_TRUE(m.cloud.labels.empty());
}

TEST(BagPointCloud2, EncoderRoundTrip) {
  const PointCloud cloud = test::random_cloud(300, 5);
  RosHeader header;
  header.stamp_sec = 12;
  header.stamp_nanosec = 345;
  header.frame_id = "velodyne";
  const PointCloud2Message m = decode_point_cloud2(encode_point_cloud2(header, cloud));
  EXPECT_TRUE(test::same_points(m.cloud.points, cloud));
  EXPECT_EQ(m.header.frame_id, "velodyne");
  EXPECT_EQ(m.header.stamp_nanosec, 345u);
  EXPECT_EQ(m.width, 300u);
  EXPECT_EQ(m.height, 1u);
  EXPECT_EQ(decode_point_cloud2(encode_point_cloud2(header, {})).cloud.points.size(), 0u);
}

TEST(BagPointCloud2, MalformedCloudsAreRefusedByName) {
  Cloud2 c = shuffled_cloud(false, false);
  c.fields.erase(c.fields.begin() + 3);  // no x
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); }, {"PointCloud2", "no field 'x'"}));

  c = shuffled_cloud(false, false);
  c.row_step = 40;  // 40 * 1 != 48 bytes of data
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); }, {"row_step 40", "48", "data holds 48 bytes"}));

  c = shuffled_cloud(false, false);
  c.width = 3;  // 3 * 24 = 72 > row_step 48
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); }, {"row_step 48", "width 3", "72"}));

  c = shuffled_cloud(false, false);
  c.fields[4].offset = 22;  // rgb 22 + 4 > 24
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); }, {"fields[rgb]", "26", "point_step 24"}));

  c = shuffled_cloud(false, false);
  c.fields[3].datatype = 5;  // x as INT32
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); }, {"fields[x]", "INT32", "FLOAT32 or FLOAT64"}));

  c = shuffled_cloud(false, false);
  c.announced_data_size = 120000;
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(c.cdr()); },
                            {"PointCloud2.data: 120000 bytes announced at offset", "49 left"}));
}

TEST(BagPointCloud2, TruncatedAtEveryByteIsAnIoError) {
  const std::string cdr = shuffled_cloud(false, false).cdr();
  for (size_t n = 0; n < cdr.size(); ++n) {
    EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(cdr.substr(0, n)); }, {"PointCloud2"})) << n;
  }
}

// An odometry message with known values: orientation given unnormalised (twice a unit
// quaternion), which the decoder normalises.
std::string odometry_cdr(bool big_endian, double qscale) {
  Cdr c(big_endian);
  c.header(100, 5, "map").str("base_link");
  c.put(1.5).put(-2.5).put(3.25);  // position
  const double h = std::sqrt(0.5);
  c.put(0.0).put(0.0).put(h * qscale).put(h * qscale);  // 90 degrees about z
  for (int i = 0; i < 36 + 6 + 36; ++i) c.put(0.0);
  return c.bytes();
}

TEST(BagPoses, OdometryWithKnownValues) {
  for (bool big : {false, true}) {
    const StampedPose p = decode_odometry(odometry_cdr(big, 2.0));
    EXPECT_EQ(p.header.stamp_sec, 100);
    EXPECT_EQ(p.header.stamp_nanosec, 5u);
    EXPECT_EQ(p.header.frame_id, "map");
    EXPECT_EQ(p.child_frame_id, "base_link");
    EXPECT_TRUE(p.T_parent_child.translation().isApprox(Eigen::Vector3d(1.5, -2.5, 3.25)));
    const Eigen::Vector3d x = p.T_parent_child.linear() * Eigen::Vector3d::UnitX();
    EXPECT_TRUE(x.isApprox(Eigen::Vector3d::UnitY(), 1e-12)) << x.transpose();
    EXPECT_NEAR(p.T_parent_child.linear().determinant(), 1.0, 1e-12);
  }
}

TEST(BagPoses, OdometryRefusesZeroQuaternionAndShortPayloads) {
  EXPECT_TRUE(ThrowsIoError([] { decode_odometry(odometry_cdr(false, 0.0)); },
                            {"Odometry.pose.pose.orientation", "zero or non-finite quaternion"}));
  const std::string cdr = odometry_cdr(false, 1.0);
  EXPECT_TRUE(ThrowsIoError([&] { decode_odometry(cdr.substr(0, cdr.size() - 8)); },
                            {"Odometry.twist.covariance", "8 bytes announced", "0 left"}));
  std::string bad_string = cdr;
  bad_string[15] = '\x7f';  // frame_id's length (bytes 12-15) becomes 0x7f000004: past the end
  EXPECT_TRUE(ThrowsIoError([&] { decode_odometry(bad_string); },
                            {"Odometry.header.frame_id", "bytes announced at offset 16"}));
}

TEST(BagPoses, PoseStamped) {
  Cdr c;
  c.header(-3, 7, "odom").put(10.0).put(20.0).put(30.0).put(0.0).put(0.0).put(0.0).put(1.0);
  const StampedPose p = decode_pose_stamped(c.bytes());
  EXPECT_EQ(p.header.stamp_sec, -3);
  EXPECT_EQ(p.header.frame_id, "odom");
  EXPECT_EQ(p.child_frame_id, "");
  EXPECT_TRUE(p.T_parent_child.isApprox(Pose3d(Eigen::Translation3d(10, 20, 30))));
}

TEST(BagPoses, TfMessageWithTwoTransforms) {
  Cdr c(true);
  c.put<uint32_t>(2);
  c.header(1, 2, "odom").str("base_link").put(1.0).put(2.0).put(3.0).put(0.0).put(0.0).put(0.0).put(1.0);
  c.header(1, 2, "base_link").str("velodyne").put(0.0).put(0.0).put(1.8).put(1.0).put(0.0).put(0.0).put(0.0);
  const std::vector<StampedPose> tfs = decode_tf_message(c.bytes());
  ASSERT_EQ(tfs.size(), 2u);
  EXPECT_EQ(tfs[0].header.frame_id, "odom");
  EXPECT_EQ(tfs[0].child_frame_id, "base_link");
  EXPECT_TRUE(tfs[0].T_parent_child.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_EQ(tfs[1].child_frame_id, "velodyne");
  // 180 degrees about x: y -> -y.
  EXPECT_TRUE((tfs[1].T_parent_child.linear() * Eigen::Vector3d::UnitY()).isApprox(-Eigen::Vector3d::UnitY()));

  std::vector<StampedPose> round = decode_tf_message(encode_tf_message(tfs));
  ASSERT_EQ(round.size(), 2u);
  EXPECT_TRUE(round[1].T_parent_child.isApprox(tfs[1].T_parent_child, 1e-12));
  EXPECT_EQ(round[1].header.frame_id, "base_link");

  Cdr forged;
  forged.put<uint32_t>(100000000);
  EXPECT_TRUE(ThrowsIoError([&] { decode_tf_message(forged.bytes()); }, {"TFMessage.transforms", "100000000"}));
}

TEST(BagPoses, OdometryEncoderRoundTrip) {
  StampedPose in;
  in.header.stamp_sec = 42;
  in.header.frame_id = "map";
  in.child_frame_id = "base";
  in.T_parent_child = Eigen::Translation3d(1, 2, 3) * Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized());
  const StampedPose out = decode_odometry(encode_odometry(in));
  EXPECT_TRUE(out.T_parent_child.isApprox(in.T_parent_child, 1e-12));
  EXPECT_EQ(out.child_frame_id, "base");
  EXPECT_EQ(out.header.stamp_sec, 42);
}

TEST(BagCdr, EncapsulationsOtherThanPlainCdrAreRefused) {
  std::string cdr = odometry_cdr(false, 1.0);
  cdr[1] = 0x03;
  EXPECT_TRUE(ThrowsIoError([&] { decode_odometry(cdr); }, {"Odometry", "PL_CDR", "not supported"}));
  cdr[1] = 0x07;
  EXPECT_TRUE(ThrowsIoError([&] { decode_odometry(cdr); }, {"unknown CDR encapsulation", "0x07"}));
  EXPECT_TRUE(ThrowsIoError([] { decode_pose_stamped(std::string("\0\1", 2)); }, {"PoseStamped", "2 bytes"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
