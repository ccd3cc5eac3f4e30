// Tracking between fixes (issue 15): a vehicle that localized once knows where it is, up to its
// odometry's drift since. The Tracker keeps T_map_odom from the last fix (a LOCALIZED reply's
// T_map_local, "local" being the vehicle's odometry frame) and sends it as the prior of the next
// query, with a radius that grows with the distance driven since that fix:
//
//   radius = initial_radius_m + growth_per_m * (odometer - odometer at the fix)
//
// (initial: the fix's own error plus margin; growth: LiDAR odometry drifts ~1 % of the
// distance, 5 % leaves room for a worse one). It queries globally (no prior) at start-up, when
// the radius has grown past max_radius_m, and after failures_before_global tracked queries in a
// row without a fix (then tracking resumes), so a wrong prior costs a few queries, never a
// false pose. No sockets: a caller sends the request it prepares (Client, or in-process).
#pragma once

#include <segmatch/api/protocol.h>

namespace segmatch {
namespace api {

struct TrackerConfig {
  double initial_radius_m = 3.0;
  double growth_per_m = 0.05;
  double max_radius_m = 30.0;
  double heading_tolerance_deg = 5.0;
  int failures_before_global = 3;
  void validate() const;  // throws std::invalid_argument naming the field
};

enum class TrackMode { kGlobal, kTracked };
const char* to_string(TrackMode mode);

class Tracker {
 public:
  explicit Tracker(const TrackerConfig& config = {});

  // Sets (tracked) or clears (global) the request's prior: flag bits 0 and 2, the prior pose,
  // radius and heading tolerance. odometer_m: distance the vehicle drove so far.
  TrackMode prepare(LocalizeRequest& request, double odometer_m);
  // The reply to the request prepared last. LOCALIZED is a fix.
  void update(const LocalizeReply& reply, double odometer_m);

  bool has_fix() const { return has_fix_; }
  const Pose3d& T_map_odom() const { return T_map_odom_; }
  // The prior's radius after driving to odometer_m (meaningful with a fix).
  double radius_m(double odometer_m) const;
  int failures_in_a_row() const { return failures_; }

 private:
  TrackerConfig config_;
  bool has_fix_ = false;
  Pose3d T_map_odom_ = Pose3d::Identity();
  double fix_odometer_m_ = 0.0;
  int failures_ = 0;
  TrackMode last_mode_ = TrackMode::kGlobal;
};

}  // namespace api
}  // namespace segmatch
