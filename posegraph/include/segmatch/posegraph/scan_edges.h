// LiDAR registration between consecutive nodes ("scan edges"): each new scan is aligned by ICP
// onto the few scans before it, starting from the odometry's step. The LiDAR measures
// distances in metres, so these edges see what loops cannot: a loop that returns to the same
// place still closes under an odometry that overestimates every step by 0.3 %, while scans
// 1 m apart tell the true 1 m. Wheel odometry (scale, yaw-rate bias) is the case they are for;
// LiDAR-inertial odometry is already this good (docs/loop-closure.md).
//
// A registration becomes an edge only when it is plausible: enough of the scan lands on the
// previous ones (fitness) and it stays near the odometry's step (a failed ICP in a corridor
// slides along it). The edge still carries the graph's robust loss.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/core/verification/verification.h"

#include <deque>
#include <optional>

namespace segmatch::posegraph {

struct ScanMatchConfig {
  float voxel_m = 0.3f;       // scans are thinned to one point per voxel of this size
  float min_range_m = 1.0f;   // points nearer than this are dropped (the vehicle itself)
  float max_range_m = 60.0f;  // and farther (sparse, where a small rotation moves points most)
  int target_scans = 3;       // the new scan is aligned onto this many previous scans, merged
  float min_fitness = 0.5f;   // fraction of the scan's points within max_correspondence_m
  // The registration may differ from the odometry's step by at most this (metres, plus
  // max_deviation_fraction of the step's length; degrees).
  double max_deviation_m = 0.5, max_deviation_fraction = 0.2, max_deviation_deg = 5.0;
  RefineConfig icp = default_icp();
  static RefineConfig default_icp() {
    RefineConfig c;
    c.max_correspondence_m = 1.0f;
    c.max_query_points = 4000;
    c.max_iterations = 40;
    return c;
  }
  void validate() const;  // throws std::invalid_argument naming the field
};

struct ScanStep {
  bool accepted = false;
  Pose3d T_previous_this = Pose3d::Identity();  // the registration (previous node -> this node)
  float fitness = 0, rmse_m = 0;
  const char* rejected_because = "";  // when not accepted
};

// Feed scans in node order. The first scan gives no step.
class ScanMatcher {
 public:
  explicit ScanMatcher(const ScanMatchConfig& config = {});
  // scan: the node's points in its sensor frame; T_odom_sensor: the odometry's pose of it.
  std::optional<ScanStep> add(const PointCloud& scan, const Pose3d& T_odom_sensor);

 private:
  struct Kept {
    PointCloud points;   // thinned, sensor frame
    Pose3d T_last_this;  // this scan's pose in the newest kept scan's frame
  };
  ScanMatchConfig config_;
  std::deque<Kept> kept_;  // newest first
  Pose3d T_odom_last_ = Pose3d::Identity();
};

}  // namespace segmatch::posegraph
