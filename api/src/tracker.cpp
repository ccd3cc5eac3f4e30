#include "segmatch/api/tracker.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace segmatch {
namespace api {

void TrackerConfig::validate() const {
  auto finite_at_least = [](double v, double lo, const char* what) {
    if (!(v >= lo) || !std::isfinite(v)) throw std::invalid_argument(std::string(what));
  };
  finite_at_least(min_radius_m, 1e-9, "min_radius_m must be finite and > 0");
  finite_at_least(drift_per_m, 0.0, "drift_per_m must be finite and >= 0");
  finite_at_least(radius_sigmas, 1e-9, "radius_sigmas must be finite and > 0");
  finite_at_least(min_fix_sigma_m, 0.0, "min_fix_sigma_m must be finite and >= 0");
  if (!(max_radius_m >= min_radius_m) || !std::isfinite(max_radius_m))
    throw std::invalid_argument("max_radius_m must be finite and >= min_radius_m");
  finite_at_least(heading_tolerance_deg, 0.0, "heading_tolerance_deg must be finite and >= 0");
  finite_at_least(gate_chi2, 1e-9, "gate_chi2 must be finite and > 0");
  if (failures_before_global < 1) throw std::invalid_argument("failures_before_global must be >= 1");
  if (max_rejections < 1) throw std::invalid_argument("max_rejections must be >= 1");
}

const char* to_string(TrackMode mode) { return mode == TrackMode::kTracked ? "tracked" : "global"; }

const char* to_string(TrackUpdate update) {
  switch (update) {
    case TrackUpdate::kFix: return "fix";
    case TrackUpdate::kRejected: return "rejected";
    case TrackUpdate::kFailure: return "failure";
  }
  return "unknown";
}

namespace {

// The reply's horizontal position covariance (revision 7), zero when it has none.
Eigen::Matrix2d horizontal_covariance(const LocalizeReply& reply) {
  if (!reply.detail || !reply.detail->estimate) return Eigen::Matrix2d::Zero();
  return covariance_matrix(reply.detail->estimate->covariance_upper).block<2, 2>(3, 3);
}

}  // namespace

Tracker::Tracker(const TrackerConfig& config) : config_(config) { config_.validate(); }

double Tracker::sigma_m(double odometer_m) const {
  const double driven = std::max(0.0, odometer_m - fix_odometer_m_);
  return std::hypot(fix_sigma_m_, config_.drift_per_m * driven);
}

double Tracker::radius_m(double odometer_m) const {
  return std::max(config_.min_radius_m, config_.radius_sigmas * sigma_m(odometer_m));
}

TrackMode Tracker::prepare(LocalizeRequest& request, double odometer_m) {
  const bool tracked =
      has_fix_ && radius_m(odometer_m) <= config_.max_radius_m && failures_ < config_.failures_before_global;
  sensor_local_ = request.sensor_position_local;
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

bool Tracker::passes_gate(const LocalizeReply& reply, double odometer_m) const {
  if (!has_fix_) return true;
  const Eigen::Vector2d innovation = (reply.T_map_local * sensor_local_ - T_map_odom_ * sensor_local_).head<2>();
  const double s = sigma_m(odometer_m);
  const Eigen::Matrix2d S = s * s * Eigen::Matrix2d::Identity() + horizontal_covariance(reply);
  return innovation.dot(S.ldlt().solve(innovation)) <= config_.gate_chi2;
}

TrackUpdate Tracker::update(const LocalizeReply& reply, double odometer_m) {
  if (reply.status != LocalizeStatus::kLocalized) {
    // A failed global query resets the count: tracking resumes from the last fix.
    failures_ = last_mode_ == TrackMode::kGlobal ? 0 : failures_ + 1;
    return TrackUpdate::kFailure;
  }
  if (!passes_gate(reply, odometer_m)) {
    ++rejections_total_;
    ++failures_;
    if (++rejections_ >= config_.max_rejections) has_fix_ = false, rejections_ = 0, failures_ = 0;
    return TrackUpdate::kRejected;
  }
  has_fix_ = true;
  T_map_odom_ = reply.T_map_local;
  fix_odometer_m_ = odometer_m;
  const Eigen::Matrix2d answer = horizontal_covariance(reply);
  const double largest =
      answer.isZero() ? 0.0 : Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(answer).eigenvalues()(1);
  fix_sigma_m_ = std::max(config_.min_fix_sigma_m, std::sqrt(std::max(0.0, largest)));
  failures_ = 0;
  rejections_ = 0;
  return TrackUpdate::kFix;
}

}  // namespace api
}  // namespace segmatch
