// Tracking between fixes (issues 15 and 33): a vehicle that localized once knows where it is, up
// to its odometry's drift since. The Tracker is a filter on the vehicle's map pose:
//
// - predict: T_map_odom from the last fix (a LOCALIZED reply's T_map_local, "local" being the
//   vehicle's odometry frame), with a horizontal 1-sigma that grows with the distance driven:
//     sigma(d) = sqrt(sigma_fix^2 + (drift_per_m * d)^2)
//   sigma_fix from the fix's reported covariance (revision 7; at least min_fix_sigma_m);
// - ask: the prediction is the next query's prior, radius radius_sigmas * sigma (at least
//   min_radius_m), which lets the server answer by registration (core/registration.h);
// - correct: a LOCALIZED answer whose sensor position lies farther from the prediction than a
//   chi-square gate of prediction plus answer covariance allows is rejected: reported, counted,
//   never a fix. After max_rejections rejections in a row the tracker drops its fix (the
//   prediction itself is then the suspect) and starts over from the next answer.
//
// It queries globally (no prior) at start-up, once the radius has grown past max_radius_m, and
// after failures_before_global tracked queries in a row without a fix (then tracking resumes),
// so a wrong prior costs a few queries, never a false pose. No sockets: a caller sends the
// request it prepares (Client, or in-process).
#pragma once

#include <segmatch/api/protocol.h>

namespace segmatch {
namespace api {

struct TrackerConfig {
  double min_radius_m = 3.0;
  // LiDAR(-inertial) odometry drifts ~0.5-1 % of the distance; 2 % as one sigma leaves room.
  double drift_per_m = 0.02;
  double radius_sigmas = 3.0;
  double min_fix_sigma_m = 0.05;
  double max_radius_m = 30.0;
  double heading_tolerance_deg = 5.0;
  // Tracked failures in a row before a global query. Most come from the place, not the prior:
  // an unmapped street, or a local cloud that is mostly one. Back on a mapped street a tracked
  // query is answered from the newest scans alone (tracking on the surface layer), where a
  // global one needs the whole cloud to be mapped: with 3, riverside02 went global at frame 117,
  // 10 m back on the map, and missed it; with 6 it was tracked and answered (docs/how-defaults-were-chosen.md).
  int failures_before_global = 6;
  // Squared Mahalanobis distance of the horizontal innovation: chi-square with 2 degrees of
  // freedom at 99.9 %.
  double gate_chi2 = 13.82;
  int max_rejections = 2;
  void validate() const;  // throws std::invalid_argument naming the field
};

enum class TrackMode { kGlobal, kTracked };
const char* to_string(TrackMode mode);

// What update() made of a reply.
enum class TrackUpdate { kFix, kRejected, kFailure };
const char* to_string(TrackUpdate update);

// Whether a request with a prior of radius_m and the newest scans may ask the server to track on
// the surface layer first (revision 11: LOCALIZE bit 6, LOCALIZE_SEGMENTS bit 5): the prior is
// given and no wider than the map's max_tracked_radius_m (core/localizer.h: the correlative
// search's max_radius_m when it is on, else registration.max_prior_radius_m); wider ones are not
// tracked.
inline bool can_track(bool has_prior, bool has_newest_scans, double radius_m, double max_prior_radius_m) {
  return has_prior && has_newest_scans && radius_m > 0.0 && radius_m <= max_prior_radius_m;
}
// Sets LOCALIZE bit 6 when can_track holds for the request.
inline void ask_to_track_first(LocalizeRequest& request, double max_prior_radius_m) {
  if (can_track(request.flags & kFlagHasPrior, request.flags & kFlagNewestScans, request.prior_radius_m,
                max_prior_radius_m))
    request.flags |= kFlagTrack;
}

class Tracker {
 public:
  explicit Tracker(const TrackerConfig& config = {});

  // Sets (tracked) or clears (global) the request's prior: flag bits 0 and 2, the prior pose,
  // radius and heading tolerance. odometer_m: distance the vehicle drove so far.
  TrackMode prepare(LocalizeRequest& request, double odometer_m);
  // The reply to the request prepared last. A LOCALIZED reply is a fix unless the gate rejects it.
  TrackUpdate update(const LocalizeReply& reply, double odometer_m);

  bool has_fix() const { return has_fix_; }
  const Pose3d& T_map_odom() const { return T_map_odom_; }
  // The prediction's horizontal 1-sigma and the prior's radius after driving to odometer_m
  // (meaningful with a fix).
  double sigma_m(double odometer_m) const;
  double radius_m(double odometer_m) const;
  int failures_in_a_row() const { return failures_; }
  int rejections() const { return rejections_total_; }  // answers the gate rejected so far

 private:
  bool passes_gate(const LocalizeReply& reply, double odometer_m) const;

  TrackerConfig config_;
  bool has_fix_ = false;
  Pose3d T_map_odom_ = Pose3d::Identity();
  double fix_odometer_m_ = 0.0, fix_sigma_m_ = 0.0;
  int failures_ = 0, rejections_ = 0, rejections_total_ = 0;
  TrackMode last_mode_ = TrackMode::kGlobal;
  Eigen::Vector3d sensor_local_ = Eigen::Vector3d::Zero();  // of the request prepared last
};

}  // namespace api
}  // namespace segmatch
