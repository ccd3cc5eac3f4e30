// Sequence: finds the scans of a recording, loads and checks its poses, times and labels.
#include <segmatch/io/pose_io.h>
#include <segmatch/io/sequence.h>

#include <algorithm>
#include <filesystem>
#include <stdexcept>

#include "cloud_internal.h"
#include "io_util.h"

namespace segmatch {
namespace io {

namespace {

namespace fs = std::filesystem;

// Nominal scan period used when a sequence has no times.txt (10 Hz spinning LiDAR).
constexpr double kDefaultScanPeriod = 0.1;

// Regular files in `dir` with extension `ext`, sorted by name (scans are numbered).
std::vector<std::string> list_files(const fs::path& dir, const std::string& ext) {
  std::vector<std::string> files;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return files;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file(ec) && detail::extension_lower(it->path().string()) == ext) {
      files.push_back(it->path().string());
    }
  }
  if (ec) detail::fail(dir.string(), "cannot list folder: " + ec.message());
  std::sort(files.begin(), files.end());
  return files;
}

std::string stem(const std::string& path) { return fs::path(path).stem().string(); }

std::string count_mismatch(size_t scans, size_t n, const std::string& what, const std::string& file) {
  return std::to_string(scans) + " scans but " + std::to_string(n) + " " + what + " in " + file;
}

void check_labels_match(const std::string& folder, const std::vector<std::string>& scans,
                        const std::vector<std::string>& labels) {
  if (labels.size() != scans.size()) {
    detail::fail(folder, count_mismatch(scans.size(), labels.size(), "label files", "labels/"));
  }
  for (size_t i = 0; i < scans.size(); ++i) {
    if (stem(scans[i]) != stem(labels[i])) {
      detail::fail(labels[i], "does not match scan " + scans[i] + " (labels are paired with scans by name)");
    }
  }
}

void require_file(const std::string& path, const std::string& why) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw IoError("missing file: " + path + " (" + why + ")");
}

bool poses_in_camera_frame(SequenceLayout layout, PoseFrame frame) {
  if (frame == PoseFrame::kAuto) return layout == SequenceLayout::kKitti;
  return frame == PoseFrame::kCamera;
}

}  // namespace

Sequence Sequence::open(const std::string& folder, const SequenceOptions& options) {
  std::error_code ec;
  if (!fs::exists(folder, ec)) throw IoError("missing folder: " + folder);
  if (BagReader::is_bag(folder)) return open_bag(folder, options);
  if (options.bag.any())
    detail::fail(folder,
                 "is a folder of scans, not a ROS 2 bag: --points-topic, --pose-topic, --map-frame and --sensor-frame "
                 "are for bags");
  if (!fs::is_directory(folder, ec)) detail::fail(folder, "is not a folder");
  const fs::path root(folder);

  Sequence seq;
  seq.folder_ = folder;
  seq.scan_paths_ = list_files(root / "velodyne", ".bin");
  if (!seq.scan_paths_.empty()) {
    seq.layout_ = SequenceLayout::kKitti;
    seq.has_labels_ = fs::is_directory(root / "labels", ec);
    if (seq.has_labels_) {
      seq.label_paths_ = list_files(root / "labels", ".label");
      check_labels_match(folder, seq.scan_paths_, seq.label_paths_);
    }
  } else {
    seq.layout_ = SequenceLayout::kPcdKeyframes;
    seq.scan_paths_ = list_files(root / "scans", ".pcd");
    if (seq.scan_paths_.empty()) seq.scan_paths_ = list_files(root, ".pcd");
    if (seq.scan_paths_.empty()) {
      detail::fail(folder, "no scans found: expected velodyne/NNNNNN.bin or scans/NNNNNN.pcd");
    }
    seq.has_labels_ = detail::pcd_has_field(seq.scan_paths_.front(), "label");
  }
  const size_t n = seq.scan_paths_.size();

  const std::string poses_path = options.poses_path.empty() ? (root / "poses.txt").string() : options.poses_path;
  require_file(poses_path, "a sequence needs one pose per scan");
  Poses poses = read_poses(poses_path);
  if (poses.size() != n) {
    detail::fail(folder, count_mismatch(n, poses.size(), "poses", fs::path(poses_path).filename().string()));
  }
  if (poses_in_camera_frame(seq.layout_, options.pose_frame)) {
    const std::string calib_path = (root / "calib.txt").string();
    require_file(calib_path, "needed to convert camera-frame poses to the LiDAR frame");
    poses = camera_to_lidar_poses(poses, read_kitti_calib(calib_path).T_cam0_velo);
  }
  seq.T_world_lidar_ = std::move(poses);

  const std::string times_path = (root / "times.txt").string();
  seq.has_times_ = fs::exists(times_path, ec);
  if (seq.has_times_) {
    seq.times_ = read_times(times_path);
    if (seq.times_.size() != n) detail::fail(folder, count_mismatch(n, seq.times_.size(), "times", "times.txt"));
  } else {
    for (size_t i = 0; i < n; ++i) seq.times_.push_back(static_cast<double>(i) * kDefaultScanPeriod);
  }
  return seq;
}

std::string Sequence::scan_path(size_t i) const {
  if (layout_ == SequenceLayout::kBag && i < bag_scans_.size()) return folder_ + "#" + std::to_string(i);
  if (i >= size()) {
    throw std::out_of_range("Sequence: scan index " + std::to_string(i) + " out of range (" + std::to_string(size()) +
                            " scans in " + folder_ + ")");
  }
  return scan_paths_[i];
}

CloudData Sequence::scan(size_t i) const {
  if (layout_ == SequenceLayout::kBag) {
    if (i >= bag_scans_.size()) (void)scan_path(i);  // the out_of_range of a folder
    std::string bytes;
    {
      const std::lock_guard<std::mutex> lock(*bag_mutex_);
      bytes = bag_->data(bag_scans_[i]);
    }
    PointCloud2Message m = decode_point_cloud2(bytes);
    m.cloud.rings = std::move(m.rings);
    return std::move(m.cloud);
  }
  const std::string path = scan_path(i);
  if (layout_ == SequenceLayout::kPcdKeyframes) return read_pcd(path);
  if (label_paths_.empty()) return read_kitti_bin(path);
  return detail::read_kitti_bin_labeled(path, label_paths_[i]);
}

}  // namespace io
}  // namespace segmatch
