// A recorded sequence: scan files on disk plus one pose (and time) per scan.
//
// Two layouts are recognised:
//   KITTI:         <folder>/velodyne/NNNNNN.bin, poses.txt (camera frame) + calib.txt,
//                  optional times.txt and labels/NNNNNN.label (SemanticKITTI)
//   PCD keyframes: <folder>/scans/NNNNNN.pcd (or <folder>/*.pcd), poses.txt (LiDAR frame),
//                  optional times.txt
//   ROS 2 bag:     an .mcap or .db3 file, or a rosbag2 folder (metadata.yaml): one scan per
//                  PointCloud2 message, its pose interpolated at the cloud's stamp (BagOptions)
// open() checks that everything is consistent (counts, calibration) so that a broken dataset
// fails at once with a clear message instead of half-way through a run. Scans themselves are
// read lazily by scan(i).
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/io/bag.h>
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

#include <cstddef>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace segmatch {
namespace io {

enum class SequenceLayout { kKitti, kPcdKeyframes, kBag };
enum class PoseFrame { kAuto, kCamera, kLidar };

// Which messages of a bag make the sequence (bag.h). Poses come from one of: pose_topic
// (nav_msgs/msg/Odometry or geometry_msgs/msg/PoseStamped); /tf and /tf_static, the transform of
// sensor_frame (default: the clouds' frame_id) in map_frame; or SequenceOptions::poses_path (TUM,
// matched by time). With none given: the only Odometry or PoseStamped topic, else /tf with the
// root of the clouds' frame as map_frame. Each cloud's pose is interpolated at its header stamp
// (slerp); clouds outside the poses' time span are skipped and counted.
struct BagOptions {
  std::string points_topic;  // default: the only PointCloud2 topic (an error lists several)
  std::string pose_topic;
  std::string map_frame, sensor_frame;  // poses from /tf: both, or map_frame alone
  bool any() const {
    return !points_topic.empty() || !pose_topic.empty() || !map_frame.empty() || !sensor_frame.empty();
  }
};

struct SequenceOptions {
  std::string poses_path;                   // override; default <folder>/poses.txt
  PoseFrame pose_frame = PoseFrame::kAuto;  // kAuto: KITTI => camera (needs calib.txt),
                                            //        PCD keyframes => LiDAR
  BagOptions bag;                           // a bag only; given for a folder of scans: IoError
};

class Sequence {
 public:
  // Throws IoError when the folder is missing, holds no scans, or when poses / times /
  // labels / calibration are missing or do not match the scans. When both velodyne/ and
  // scans/ exist, the KITTI layout wins.
  static Sequence open(const std::string& folder, const SequenceOptions& options = {});

  SequenceLayout layout() const { return layout_; }
  size_t size() const { return layout_ == SequenceLayout::kBag ? bag_scans_.size() : scan_paths_.size(); }
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
  // The folder, or the bag's path.
  const std::string& folder() const { return folder_; }
  // A bag: where its scans and poses came from, and the clouds skipped ("" for a folder).
  const std::string& source_note() const { return source_note_; }

 private:
  Sequence() = default;
  static Sequence open_bag(const std::string& path, const SequenceOptions& options);

  std::string folder_;
  SequenceLayout layout_ = SequenceLayout::kKitti;
  std::vector<std::string> scan_paths_;
  std::vector<std::string> label_paths_;  // KITTI only, empty when there are no labels
  Poses T_world_lidar_;
  std::vector<double> times_;
  bool has_times_ = false;
  bool has_labels_ = false;
  // A bag: its reader (shared by copies, reads serialised by bag_mutex_) and each scan's message.
  std::shared_ptr<const BagReader> bag_;
  std::shared_ptr<std::mutex> bag_mutex_;
  std::vector<BagMessageRef> bag_scans_;
  std::string source_note_;
};

}  // namespace io
}  // namespace segmatch
