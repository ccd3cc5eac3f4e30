// A recorded sequence written as an MCAP bag (segmatch-sim --bag): what a user's ROS 2 drive
// looks like to the tools, and the interoperability tests' reference layout.
#include <segmatch/io/bag.h>
#include <segmatch/io/sequence.h>

#include <algorithm>
#include <cmath>

namespace segmatch {
namespace io {

namespace {

RosHeader header_at(double t_s, const std::string& frame) {
  RosHeader h;
  const double sec = std::floor(t_s);
  h.stamp_sec = static_cast<int32_t>(sec);
  h.stamp_nanosec = static_cast<uint32_t>(std::llround((t_s - sec) * 1e9) % 1000000000LL);
  h.frame_id = frame;
  return h;
}

}  // namespace

void write_sequence_bag(const Sequence& sequence, const std::string& path, const SequenceBagOptions& options,
                        const std::function<void(size_t, size_t)>& progress) {
  McapWriter bag(path, options.mcap);
  const uint16_t points = bag.add_channel(options.points_topic, "sensor_msgs/msg/PointCloud2");
  const uint16_t odom = bag.add_channel(options.odom_topic, "nav_msgs/msg/Odometry");
  const uint16_t tf = bag.add_channel("/tf", "tf2_msgs/msg/TFMessage");
  for (size_t i = 0; i < sequence.size(); ++i) {
    const double t = sequence.times()[i];
    const uint64_t log_time_ns = static_cast<uint64_t>(std::llround(std::max(0.0, t) * 1e9));
    bag.write(points, log_time_ns, encode_point_cloud2(header_at(t, options.sensor_frame), sequence.scan(i).points));
    StampedPose pose;
    pose.header = header_at(t, options.map_frame);
    pose.child_frame_id = options.sensor_frame;
    pose.T_parent_child = sequence.poses()[i];
    bag.write(odom, log_time_ns, encode_odometry(pose));
    bag.write(tf, log_time_ns, encode_tf_message({pose}));
    if (progress) progress(i + 1, sequence.size());
  }
  bag.close();
}

}  // namespace io
}  // namespace segmatch
