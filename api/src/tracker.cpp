#include "segmatch/api/tracker.h"

#include <cmath>
#include <stdexcept>

namespace segmatch {
namespace api {

void TrackerConfig::validate() const {
  if (!(initial_radius_m > 0.0) || !std::isfinite(initial_radius_m))
    throw std::invalid_argument("initial_radius_m must be finite and > 0");
  if (!(growth_per_m >= 0.0) || !std::isfinite(growth_per_m)) throw std::invalid_argument("growth_per_m must be finite and >= 0");
  if (!(max_radius_m >= initial_radius_m) || !std::isfinite(max_radius_m))
    throw std::invalid_argument("max_radius_m must be finite and >= initial_radius_m");
  if (!(heading_tolerance_deg >= 0.0) || !std::isfinite(heading_tolerance_deg))
    throw std::invalid_argument("heading_tolerance_deg must be finite and >= 0");
  if (failures_before_global < 1) throw std::invalid_argument("failures_before_global must be >= 1");
}

const char* to_string(TrackMode mode) { return mode == TrackMode::kTracked ? "tracked" : "global"; }

Tracker::Tracker(const TrackerConfig& config) : config_(config) { config_.validate(); }

double Tracker::radius_m(double odometer_m) const {
  return config_.initial_radius_m + config_.growth_per_m * std::max(0.0, odometer_m - fix_odometer_m_);
}

TrackMode Tracker::prepare(LocalizeRequest& request, double odometer_m) {
  const bool tracked = has_fix_ && radius_m(odometer_m) <= config_.max_radius_m &&
                       failures_ < config_.failures_before_global;
  request.flags &= ~(kFlagHasPrior | kFlagPriorHeading);
  if (tracked) {
    request.flags |= kFlagHasPrior | kFlagPriorHeading;
    request.T_map_local_prior = T_map_odom_;
    request.prior_radius_m = radius_m(odometer_m);
    request.prior_heading_tolerance_deg = config_.heading_tolerance_deg;
  } else {
    request.T_map_local_prior = Pose3d::Identity();
    request.prior_radius_m = 0.0;
  }
  last_mode_ = tracked ? TrackMode::kTracked : TrackMode::kGlobal;
  return last_mode_;
}

void Tracker::update(const LocalizeReply& reply, double odometer_m) {
  if (reply.status == LocalizeStatus::kLocalized) {
    has_fix_ = true;
    T_map_odom_ = reply.T_map_local;
    fix_odometer_m_ = odometer_m;
    failures_ = 0;
    return;
  }
  // A failed global query resets the count: tracking resumes from the last fix.
  failures_ = last_mode_ == TrackMode::kGlobal ? 0 : failures_ + 1;
}

}  // namespace api
}  // namespace segmatch
