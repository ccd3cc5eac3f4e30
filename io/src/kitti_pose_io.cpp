// KITTI odometry poses.txt and calib.txt, and the camera <-> LiDAR frame change.
#include <segmatch/io/pose_io.h>

#include <Eigen/SVD>
#include <cstdio>

#include "io_util.h"

namespace segmatch {
namespace io {

namespace {

// Text files round to ~6 digits, so R^T R - I of a genuine rotation is ~1e-6; anything
// beyond this tolerance is a wrong column order, a scale, or garbage.
constexpr double kOrthonormalTolerance = 1e-3;

// Builds a pose from a row-major 3x4 [R|t], rejecting non-rotations and snapping small
// rounding errors back onto SO(3) (nearest rotation via SVD).
Pose3d pose_from_row_major(const std::string& where, const double* v) {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = v[r * 4 + c];
    t(r) = v[r * 4 + 3];
  }
  const double error = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (error > kOrthonormalTolerance) {
    char text[64];
    std::snprintf(text, sizeof(text), "%.3g", error);
    detail::fail(where, std::string("rotation is not orthonormal (|R^T R - I| = ") + text + ")");
  }
  if (R.determinant() < 0) detail::fail(where, "rotation is a reflection (det R < 0)");
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Pose3d pose = Pose3d::Identity();
  pose.linear() = svd.matrixU() * svd.matrixV().transpose();
  pose.translation() = t;
  return pose;
}

void append_row_major(std::string* out, const Pose3d& pose) {
  const Eigen::Matrix<double, 3, 4> m = pose.matrix().topRows<3>();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      if (r + c > 0) *out += ' ';
      detail::append_number(out, m(r, c));
    }
  }
  *out += '\n';
}

// KITTI's calib.txt layout: "KEY: " then 12 numbers in %.12e.
std::string calib_line(const char* key, const double* values) {
  std::string line = key;
  char number[32];
  for (int i = 0; i < 12; ++i) {
    std::snprintf(number, sizeof(number), " %.12e", values[i]);
    line += number;
  }
  return line + "\n";
}

}  // namespace

Poses read_kitti_poses(const std::string& path) {
  const std::string text = detail::read_file(path);
  std::string_view rest(text);
  std::string_view line;
  std::vector<std::string_view> tokens;
  Poses poses;
  size_t blank_line = 0;  // first blank line seen; only allowed at the end of the file
  double values[12];
  for (size_t number = 1; detail::next_line(&rest, &line); ++number) {
    detail::split_tokens(line, &tokens);
    if (tokens.empty()) {
      if (blank_line == 0) blank_line = number;
      continue;
    }
    if (blank_line != 0) {
      detail::fail(detail::line_ref(path, blank_line),
                   "blank line before the last pose (poses are matched to scans by line)");
    }
    const std::string where = detail::line_ref(path, number);
    detail::parse_finite_numbers(where, tokens, 12, values);
    poses.push_back(pose_from_row_major(where, values));
  }
  return poses;
}

void write_kitti_poses(const std::string& path, const Poses& poses) {
  std::string text;
  text.reserve(poses.size() * 200);
  for (const Pose3d& pose : poses) append_row_major(&text, pose);
  detail::write_file(path, text);
}

KittiCalib read_kitti_calib(const std::string& path) {
  const std::string text = detail::read_file(path);
  std::string_view rest(text);
  std::string_view line;
  std::vector<std::string_view> tokens;
  for (size_t number = 1; detail::next_line(&rest, &line); ++number) {
    detail::split_tokens(line, &tokens);
    if (tokens.empty() || (tokens[0] != "Tr:" && tokens[0] != "Tr_velo_to_cam:")) continue;
    const std::string where = detail::line_ref(path, number);
    double values[12];
    detail::parse_finite_numbers(where, {tokens.begin() + 1, tokens.end()}, 12, values);
    KittiCalib calib;
    calib.T_cam0_velo = pose_from_row_major(where, values);
    return calib;
  }
  detail::fail(path, "no 'Tr:' (or 'Tr_velo_to_cam:') line with the LiDAR-to-camera calibration");
}

void write_kitti_calib(const std::string& path, const KittiCalib& calib) {
  // KITTI odometry sequence 00's rectified projection matrices: the pipeline never uses
  // them, but tools that read calib.txt expect the lines.
  static const double kP[4][12] = {
      {718.856, 0, 607.1928, 0, 0, 718.856, 185.2157, 0, 0, 0, 1, 0},
      {718.856, 0, 607.1928, -386.1448, 0, 718.856, 185.2157, 0, 0, 0, 1, 0},
      {718.856, 0, 607.1928, 45.38225, 0, 718.856, 185.2157, -0.1130887, 0, 0, 1, 0.003779761},
      {718.856, 0, 607.1928, -337.2877, 0, 718.856, 185.2157, 2.369057, 0, 0, 1, 0.004915215}};
  std::string text =
      calib_line("P0:", kP[0]) + calib_line("P1:", kP[1]) + calib_line("P2:", kP[2]) + calib_line("P3:", kP[3]);
  const Eigen::Matrix<double, 3, 4, Eigen::RowMajor> tr = calib.T_cam0_velo.matrix().topRows<3>();
  text += calib_line("Tr:", tr.data());
  detail::write_file(path, text);
}

Poses camera_to_lidar_poses(const Poses& T_cam0_cami, const Pose3d& T_cam0_velo) {
  const Pose3d T_velo_cam0 = T_cam0_velo.inverse();
  Poses out;
  out.reserve(T_cam0_cami.size());
  for (const Pose3d& P : T_cam0_cami) out.push_back(T_velo_cam0 * P * T_cam0_velo);
  return out;
}

Poses lidar_to_camera_poses(const Poses& T_velo0_veloi, const Pose3d& T_cam0_velo) {
  const Pose3d T_velo_cam0 = T_cam0_velo.inverse();
  Poses out;
  out.reserve(T_velo0_veloi.size());
  for (const Pose3d& L : T_velo0_veloi) out.push_back(T_cam0_velo * L * T_velo_cam0);
  return out;
}

}  // namespace io
}  // namespace segmatch
