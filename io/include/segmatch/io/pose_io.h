// Trajectory files: KITTI poses.txt / calib.txt / times.txt and TUM trajectories.
//
// Frames: KITTI poses.txt holds T_cam0(frame 0)_cam0(frame i), i.e. left-camera poses in the
// first camera frame. The LiDAR pipeline wants T_velo0_veloi, obtained with the calibration
// Tr = T_cam0_velo:  T_velo0_veloi = Tr^-1 * T_cam00_cam0i * Tr.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/io/error.h>

#include <string>
#include <vector>

namespace segmatch {
namespace io {

// One pose per line: 12 numbers, the row-major 3x4 matrix [R|t]. Blank trailing lines are
// fine. A NaN/Inf, a wrong number count or a rotation with |R^T R - I| > 1e-3 (or a
// reflection) raises IoError naming the line; smaller errors (rounded text) are
// re-orthonormalised.
Poses read_kitti_poses(const std::string& path);
// Writes with the shortest text that reads back to the same doubles (exact round trip).
void write_kitti_poses(const std::string& path, const Poses& poses);

struct KittiCalib {
  Pose3d T_cam0_velo = Pose3d::Identity();  // "Tr:" (odometry) or "Tr_velo_to_cam:" (object)
};
KittiCalib read_kitti_calib(const std::string& path);
// Writes P0..P3 (KITTI sequence 00's projection matrices) and "Tr:", in KITTI's %.12e layout.
void write_kitti_calib(const std::string& path, const KittiCalib& calib);

// T_velo0_veloi = Tr^-1 * T_cam0_cami * Tr, and the inverse mapping.
Poses camera_to_lidar_poses(const Poses& T_cam0_cami, const Pose3d& T_cam0_velo);
Poses lidar_to_camera_poses(const Poses& T_velo0_veloi, const Pose3d& T_cam0_velo);

// TUM RGB-D format: "t x y z qx qy qz qw" per line, '#' comments. Quaternions are normalised;
// a zero-norm quaternion raises IoError.
struct StampedPoses {
  std::vector<double> times;
  Poses poses;
};
StampedPoses read_tum(const std::string& path);
void write_tum(const std::string& path, const StampedPoses& poses);

// A trajectory in either format, told apart by the columns of its first pose line: 12 numbers
// are KITTI, 8 are TUM (its times are dropped; the poses are in file order). Anything else
// raises IoError naming the file and the count found.
Poses read_poses(const std::string& path);

// KITTI times.txt: one number (seconds) per line.
std::vector<double> read_times(const std::string& path);
void write_times(const std::string& path, const std::vector<double>& times);

}  // namespace io
}  // namespace segmatch
