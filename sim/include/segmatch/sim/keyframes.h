// Keyframes as a LiDAR SLAM front end writes them, made from a simulated traversal: each
// time the sensor has moved every_m from the previous keyframe, its last `frames` scans are
// put into the keyframe's sensor frame with the exact poses (a front end that deskews and
// registers perfectly) and voxel-downsampled. Written as the real recordings are:
//
//   DIR/scans/NNNNNN.pcd   binary PCD v0.7, x y z intensity float32 (+ label uint32 when
//                          labels are written), sensor frame
//   DIR/poses.txt          ground truth T_world_sensor, 12 numbers row-major, world = the
//                          first keyframe's sensor frame
//   DIR/odom_poses.txt     the same poses as an odometry with a systematic drift would report
//                          them (see KeyframeConfig), also starting at the identity
//   DIR/times.txt          time of each keyframe's last scan (s)
//
// io::Sequence::open reads DIR as a PCD-keyframe sequence (LiDAR-frame poses).
#pragma once

#include "segmatch/sim/lidar.h"
#include "segmatch/sim/traversal.h"

#include <functional>
#include <string>
#include <vector>

namespace segmatch::sim {

struct KeyframeConfig {
  double every_m = 0.0;  // a keyframe each time the sensor is this far (straight line) from
                         // the previous one; 0: no keyframes
  float leaf_m = 0.2f;   // voxel edge of the downsampling: one centroid per occupied voxel
  int frames = 0;        // consecutive scans integrated per keyframe, ending at it;
                         // 0: the sensor's default (default_keyframe_frames)
  // Drift of odom_poses.txt. A systematic part, the same every run: every keyframe-to-keyframe
  // step is read odom_scale_error too long and turned odom_yaw_drift_deg_per_m per metre of
  // the step to the left (an uncalibrated wheel / IMU bias rather than white noise).
  // All terms 0 (with the walks below): odom_poses.txt equals poses.txt.
  double odom_scale_error = 0.002;
  double odom_yaw_drift_deg_per_m = 0.003;
  // ... and climbs this much per metre of the step (LiDAR odometry drifts in height too).
  double odom_climb_m_per_m = 0.0;
  // LiDAR-inertial odometry also wanders: heading and pitch take a random walk, each step
  // adding a Gaussian angle of this many degrees times the square root of its length (a
  // walk's spread grows with the root of the distance: 0.04 gives 0.4 deg per 100 m). The
  // heading error turns the odometry; the pitch error only slants its steps (height drift): an
  // IMU's gravity keeps LiDAR-inertial roll and pitch from drifting, and so does the walk. With the
  // systematic terms above, about 0.3-1 deg and 0.5-1 m per 100 m, as FAST-LIO-like odometry
  // drifts (hku-loop1: 0.3 m / 0.4 deg over 64 m; riverside02: 0.19 m / 0.27 deg per 90 m, up
  // to 2.3 m / 1.3 deg per 170 m). Seeded by odom_seed (the dataset mixes in the world seed and
  // the sequence). 0: none.
  double odom_heading_walk_deg_per_sqrt_m = 0.04;
  double odom_pitch_walk_deg_per_sqrt_m = 0.02;
  uint64_t odom_seed = 1;
  bool write_labels = true;  // label field in the PCDs (majority ground-truth label per voxel)

  void validate() const;  // throws std::invalid_argument naming the bad field
};

// Scans a SLAM front end would integrate per keyframe for this sensor: 5 (0.5 s, about the
// 0.4-0.5 s between the keyframes of the hku Livox recordings) for a rosette, whose single
// frame is sparse; 1 for a spinning LiDAR.
int default_keyframe_frames(const LidarModel& model);

// Scan index of every keyframe: the first at frames - 1 (so it has all its scans), then the
// first scan at least every_m (straight line) from the previous keyframe.
std::vector<size_t> keyframe_frames(const Traversal& traversal, double every_m, int frames);

// Odometry poses with the drift of `config` (systematic terms and the seeded random walk)
// applied to every step between consecutive poses; the first pose is kept.
Poses drifted_odometry(const Poses& T_world_sensor, const KeyframeConfig& config);

struct KeyframeSummary {
  std::vector<size_t> frames;  // scan index of each keyframe
  Poses T_world_keyframe;      // in the traversal's world frame (not the keyframe world)
  size_t points = 0;           // in all keyframes
};

// Returns scan `frame` of the traversal (sensor frame, labels optional). Called from one
// thread, with frames in increasing order.
using ScanSource = std::function<SimulatedScan(size_t frame)>;

// Builds and writes the keyframes of `traversal` into out_dir (created if needed). frames
// must be resolved (> 0). Throws std::runtime_error / io::IoError naming a file it cannot write.
KeyframeSummary write_keyframes(const Traversal& traversal, const ScanSource& scans, const KeyframeConfig& config,
                                const std::string& out_dir);

}  // namespace segmatch::sim
