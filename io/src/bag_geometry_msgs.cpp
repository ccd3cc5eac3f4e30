// nav_msgs/msg/Odometry, geometry_msgs/msg/PoseStamped and tf2_msgs/msg/TFMessage in CDR.
#include "cdr.h"

#include <cmath>

namespace segmatch {
namespace io {

namespace {

using detail::CdrReader;
using detail::CdrWriter;

// A covariance or twist is read (to check the payload holds it) and discarded.
void skip_f64s(CdrReader& in, const std::string& field, int n) {
  for (int i = 0; i < n; ++i) in.f64(field.c_str());
}

// geometry_msgs/Point + Quaternion (a Pose), or Vector3 + Quaternion (a Transform): the same
// seven float64s. The quaternion is normalised; a zero or non-finite one, or a non-finite
// position, is refused rather than turned into a pose that would poison a trajectory.
Pose3d read_pose(CdrReader& in, const std::string& prefix, const char* position, const char* orientation) {
  const std::string p = prefix + "." + position, q = prefix + "." + orientation;
  Eigen::Vector3d t;
  t.x() = in.f64((p + ".x").c_str());
  const size_t at = in.offset() - 8;  // after any alignment padding
  t.y() = in.f64((p + ".y").c_str());
  t.z() = in.f64((p + ".z").c_str());
  Eigen::Quaterniond r;
  const size_t q_at = in.offset();
  r.x() = in.f64((q + ".x").c_str());
  r.y() = in.f64((q + ".y").c_str());
  r.z() = in.f64((q + ".z").c_str());
  r.w() = in.f64((q + ".w").c_str());
  if (!t.allFinite()) in.fail(p.c_str(), "non-finite value at offset " + std::to_string(at));
  const double norm = r.norm();
  if (!std::isfinite(norm) || norm < 1e-9) {
    in.fail(q.c_str(), "zero or non-finite quaternion at offset " + std::to_string(q_at));
  }
  Pose3d pose = Pose3d::Identity();
  pose.linear() = Eigen::Quaterniond(r.coeffs() / norm).toRotationMatrix();
  pose.translation() = t;
  return pose;
}

void write_pose(CdrWriter& out, const Pose3d& pose) {
  const Eigen::Vector3d t = pose.translation();
  const Eigen::Quaterniond r(pose.rotation());
  out.f64(t.x());
  out.f64(t.y());
  out.f64(t.z());
  out.f64(r.x());
  out.f64(r.y());
  out.f64(r.z());
  out.f64(r.w());
}

}  // namespace

StampedPose decode_odometry(std::string_view cdr) {
  CdrReader in(cdr, "Odometry");
  StampedPose out;
  out.header = detail::read_ros_header(in);
  out.child_frame_id = in.string("child_frame_id");
  out.T_parent_child = read_pose(in, "pose.pose", "position", "orientation");
  skip_f64s(in, "pose.covariance", 36);
  skip_f64s(in, "twist.twist", 6);
  skip_f64s(in, "twist.covariance", 36);
  return out;
}

StampedPose decode_pose_stamped(std::string_view cdr) {
  CdrReader in(cdr, "PoseStamped");
  StampedPose out;
  out.header = detail::read_ros_header(in);
  out.T_parent_child = read_pose(in, "pose", "position", "orientation");
  return out;
}

std::vector<StampedPose> decode_tf_message(std::string_view cdr) {
  CdrReader in(cdr, "TFMessage");
  // A TransformStamped takes at least 8 (stamp) + 4 + 4 (two string lengths) + 56 bytes.
  const uint32_t count = in.sequence_count("transforms", 72);
  std::vector<StampedPose> out(count);
  for (StampedPose& tf : out) {
    tf.header.stamp_sec = in.i32("transforms.header.stamp.sec");
    tf.header.stamp_nanosec = in.u32("transforms.header.stamp.nanosec");
    tf.header.frame_id = in.string("transforms.header.frame_id");
    tf.child_frame_id = in.string("transforms.child_frame_id");
    tf.T_parent_child = read_pose(in, "transforms.transform", "translation", "rotation");
  }
  return out;
}

std::string encode_odometry(const StampedPose& pose) {
  CdrWriter out;
  detail::write_ros_header(out, pose.header);
  out.string(pose.child_frame_id);
  write_pose(out, pose.T_parent_child);
  for (int i = 0; i < 36 + 6 + 36; ++i) out.f64(0.0);  // pose covariance, twist, its covariance
  return out.take();
}

std::string encode_tf_message(const std::vector<StampedPose>& transforms) {
  CdrWriter out;
  out.u32(static_cast<uint32_t>(transforms.size()));
  for (const StampedPose& tf : transforms) {
    detail::write_ros_header(out, tf.header);
    out.string(tf.child_frame_id);
    write_pose(out, tf.T_parent_child);
  }
  return out.take();
}

}  // namespace io
}  // namespace segmatch
