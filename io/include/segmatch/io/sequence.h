// A recorded sequence: scan files on disk plus one pose (and time) per scan.
//
// Two layouts are recognised:
//   KITTI:         <folder>/velodyne/NNNNNN.bin, poses.txt (camera frame) + calib.txt,
//                  optional times.txt and labels/NNNNNN.label (SemanticKITTI)
//   PCD keyframes: <folder>/scans/NNNNNN.pcd (or <folder>/*.pcd), poses.txt (LiDAR frame),
//                  optional times.txt
// open() checks that everything is consistent (counts, calibration) so that a broken dataset
// fails at once with a clear message instead of half-way through a run. Scans themselves are
// read lazily by scan(i).
#pragma once

#include <segmatch/core/types.h>
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

#include <cstddef>
#include <string>
#include <vector>

namespace segmatch {
namespace io {

enum class SequenceLayout { kKitti, kPcdKeyframes };
enum class PoseFrame { kAuto, kCamera, kLidar };

struct SequenceOptions {
  std::string poses_path;                   // override; default <folder>/poses.txt
  PoseFrame pose_frame = PoseFrame::kAuto;  // kAuto: KITTI => camera (needs calib.txt),
                                            //        PCD keyframes => LiDAR
};

class Sequence {
 public:
  // Throws IoError when the folder is missing, holds no scans, or when poses / times /
  // labels / calibration are missing or do not match the scans. When both velodyne/ and
  // scans/ exist, the KITTI layout wins.
  static Sequence open(const std::string& folder, const SequenceOptions& options = {});

  SequenceLayout layout() const { return layout_; }
  size_t size() const { return scan_paths_.size(); }
  // T_world_lidar per scan. World = first LiDAR frame for KITTI camera poses converted with
  // Tr, or whatever the file uses for LiDAR-frame poses.
  const Poses& poses() const { return T_world_lidar_; }
  // From times.txt; if absent, index * 0.1 s and has_times() is false.
  const std::vector<double>& times() const { return times_; }
  bool has_times() const { return has_times_; }
  // KITTI: labels/ folder present. PCD keyframes: the first scan has a "label" field.
  bool has_labels() const { return has_labels_; }
  std::string scan_path(size_t i) const;
  // Reads scan i and its labels. IoError on an unreadable/truncated file; std::out_of_range
  // when i >= size().
  CloudData scan(size_t i) const;
  const std::string& folder() const { return folder_; }

 private:
  Sequence() = default;

  std::string folder_;
  SequenceLayout layout_ = SequenceLayout::kKitti;
  std::vector<std::string> scan_paths_;
  std::vector<std::string> label_paths_;  // KITTI only, empty when there are no labels
  Poses T_world_lidar_;
  std::vector<double> times_;
  bool has_times_ = false;
  bool has_labels_ = false;
};

}  // namespace io
}  // namespace segmatch
