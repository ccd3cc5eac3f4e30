// A complete simulated dataset in KITTI odometry layout: a world, a first traversal
// (sequence 00, the mapping run) and a second one (sequence 01) that revisits its streets in
// both directions, with a lane offset, after the world changed.
//
//   OUT/sequences/NN/velodyne/NNNNNN.bin   float32 x y z intensity, LiDAR frame
//   OUT/sequences/NN/labels/NNNNNN.label   uint32 per point, SemanticKITTI (instance << 16 | class)
//   OUT/sequences/NN/poses.txt             camera-0 poses relative to the first frame, as KITTI
//   OUT/sequences/NN/calib.txt             P0..P3 and Tr (T_cam0_velo), KITTI 00's values
//   OUT/sequences/NN/times.txt             seconds
//   OUT/sequences/NN/odom_poses.txt        poses.txt as a drifting odometry reports them (keyframes.h)
//   OUT/ground_truth/lidar_poses_NN.txt    T_world_lidar per scan (12 numbers, shared world frame)
//   OUT/ground_truth/revisits_01_00.txt    per scan of 01: nearest scan of 00, distance, heading diff
//   OUT/ground_truth/objects_NN.csv        every object: instance, kind, position, size
//   OUT/world.png, OUT/scan.png, OUT/dataset.json
//
// With keyframes (KeyframeConfig::every_m > 0), also as a SLAM front end writes them (see
// keyframes.h), made from the scans above:
//   OUT/keyframes/NN/scans/NNNNNN.pcd, poses.txt, odom_poses.txt, times.txt
//   OUT/ground_truth/keyframe_poses_NN.txt   T_world_lidar per keyframe (shared world frame)
//   OUT/ground_truth/keyframe_frames_NN.txt  the scan of sequences/NN each keyframe ends at
#pragma once

#include "segmatch/sim/keyframes.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/traversal.h"
#include "segmatch/sim/world.h"

#include <functional>
#include <string>
#include <vector>

namespace segmatch::sim {

struct DatasetConfig {
  std::string preset = "custom";
  WorldConfig world;
  ChangeConfig change;
  DriveConfig drive_first;   // sequence 00
  DriveConfig drive_second;  // sequence 01 (inner lane, shifted)
  std::string sensor = "hdl64e";
  double first_length_m = 1200.0;  // route length of sequence 00
  // Route of sequence 00: "random" (first_length_m, preferring new streets) or "loop" (around
  // the city and along its first streets again: plan_loop_route, for loop closure).
  std::string first_route = "random";
  double second_length_m = 800.0;  // route length of sequence 01
  int threads = 0;                 // 0: one per core
  bool write_labels = true;
  bool write_images = true;
  KeyframeConfig keyframes;  // every_m 0 (default): no keyframes

  // Sets the sensor and drives both traversals with it at its mount height (to the mm), e.g.
  // 1.0 m for the handheld livox-avia. Throws std::invalid_argument on an unknown name.
  void use_sensor(const std::string& name);
  void validate() const;  // throws std::invalid_argument naming the bad field
};

// Presets: "tiny" (seconds, for tests), "demo" (about 2 km of driving with revisits),
// "city" (10+ km of streets, for scale benchmarks). Throws std::invalid_argument.
DatasetConfig dataset_preset(const std::string& name, uint64_t seed);
std::vector<std::string> dataset_preset_names();

struct DatasetSummary {
  size_t scans[2] = {0, 0};
  double length_m[2] = {0, 0};
  size_t points = 0;
  size_t objects = 0;
  size_t primitives = 0;
  double street_length_m = 0;
  size_t revisit_frames = 0;     // frames of 01 within 5 m of a frame of 00
  size_t unmapped_frames = 0;    // frames of 01 more than 30 m from every frame of 00
  size_t keyframes[2] = {0, 0};  // with keyframes
  size_t keyframe_points = 0;
  double seconds = 0;
};

// Called from the calling thread: stage name, steps done, steps total.
using ProgressFn = std::function<void(const std::string& stage, size_t done, size_t total)>;

// Generates everything into out_dir (created if needed). Throws std::runtime_error
// (or segmatch::io::IoError) naming the file on any write failure.
DatasetSummary generate_dataset(const DatasetConfig& config, const std::string& out_dir,
                                const ProgressFn& progress = {});

}  // namespace segmatch::sim
