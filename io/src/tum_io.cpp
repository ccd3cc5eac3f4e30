// TUM trajectories ("t x y z qx qy qz qw") and KITTI times.txt.
#include <segmatch/io/pose_io.h>

#include "io_util.h"

namespace segmatch {
namespace io {

namespace {

// Quaternions in text files are rounded; below this norm the direction is meaningless.
constexpr double kMinQuaternionNorm = 1e-6;

Pose3d pose_from_tum(const std::string& where, const double* v) {
  Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);  // Eigen takes w first; the file has w last
  const double norm = q.norm();
  if (norm < kMinQuaternionNorm) detail::fail(where, "quaternion has zero norm");
  q.coeffs() /= norm;
  Pose3d pose = Pose3d::Identity();
  pose.linear() = q.toRotationMatrix();
  pose.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  return pose;
}

// Calls on_line(where, tokens) for each non-blank line that is not a '#' comment.
template <typename OnLine>
void for_each_data_line(const std::string& path, OnLine on_line) {
  const std::string text = detail::read_file(path);
  std::string_view rest(text);
  std::string_view line;
  std::vector<std::string_view> tokens;
  for (size_t number = 1; detail::next_line(&rest, &line); ++number) {
    detail::split_tokens(line, &tokens);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    on_line(detail::line_ref(path, number), tokens);
  }
}

}  // namespace

StampedPoses read_tum(const std::string& path) {
  StampedPoses out;
  for_each_data_line(path, [&](const std::string& where, const std::vector<std::string_view>& tokens) {
    double v[8];
    detail::parse_finite_numbers(where, tokens, 8, v);
    out.times.push_back(v[0]);
    out.poses.push_back(pose_from_tum(where, v + 1));
  });
  return out;
}

void write_tum(const std::string& path, const StampedPoses& poses) {
  if (poses.times.size() != poses.poses.size()) {
    detail::fail(path, "cannot write " + std::to_string(poses.times.size()) + " times for " +
                           std::to_string(poses.poses.size()) + " poses");
  }
  std::string text = "# t x y z qx qy qz qw\n";
  for (size_t i = 0; i < poses.poses.size(); ++i) {
    const Pose3d& pose = poses.poses[i];
    const Eigen::Quaterniond q(pose.linear());
    const Eigen::Vector3d t = pose.translation();
    for (double v : {poses.times[i], t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) {
      detail::append_number(&text, v);
      text += ' ';
    }
    text.back() = '\n';
  }
  detail::write_file(path, text);
}

std::vector<double> read_times(const std::string& path) {
  std::vector<double> times;
  for_each_data_line(path, [&](const std::string& where, const std::vector<std::string_view>& tokens) {
    double t = 0.0;
    detail::parse_finite_numbers(where, tokens, 1, &t);
    times.push_back(t);
  });
  return times;
}

void write_times(const std::string& path, const std::vector<double>& times) {
  std::string text;
  text.reserve(times.size() * 20);
  for (double t : times) {
    detail::append_number(&text, t);
    text += '\n';
  }
  detail::write_file(path, text);
}

}  // namespace io
}  // namespace segmatch
