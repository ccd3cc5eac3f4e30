#include "query_priors.h"

#include <cmath>
#include <stdexcept>

namespace segmatch {
namespace eval {

QueryPriors::QueryPriors(const LocalizationRunConfig& config, const Poses& truth)
    : config_(config), truth_(truth), gnss_rng_(config.gnss_seed) {
  if ((config.track ? 1 : 0) + (config.gnss_sigma_m > 0.0 ? 1 : 0) + (config.wrong_prior_m > 0.0 ? 1 : 0) > 1)
    throw std::runtime_error("--track, --gnss-sigma-m and --wrong-prior-m exclude each other");
  if (!(config.wrong_prior_m >= 0.0) || !std::isfinite(config.wrong_prior_m) || !(config.wrong_prior_radius_m > 0.0) ||
      !std::isfinite(config.wrong_prior_radius_m))
    throw std::runtime_error("--wrong-prior-m must be finite and >= 0, --wrong-prior-radius-m finite and > 0");
  if (!(config.gnss_sigma_m >= 0.0) || !std::isfinite(config.gnss_sigma_m))
    throw std::runtime_error("--gnss-sigma-m must be a finite number >= 0");
}

std::string QueryPriors::prepare(api::LocalizeRequest& request, const io::ReplayQuery& q) {
  if (config_.track) return api::to_string(tracker_.prepare(request, q.odometer_m));
  if (config_.wrong_prior_m > 0.0) {
    const double angle = 2.0 * M_PI * gnss_rng_.uniform();
    Pose3d T_map_sensor = truth_[q.frame];
    T_map_sensor.translation() += config_.wrong_prior_m * Eigen::Vector3d(std::cos(angle), std::sin(angle), 0.0);
    request.flags |= api::kFlagHasPrior;
    request.T_map_local_prior = T_map_sensor * q.T_odom_sensor.inverse();
    request.prior_radius_m = config_.wrong_prior_radius_m;
    return "wrong";
  }
  if (config_.gnss_sigma_m <= 0.0) return "global";
  // A GNSS fix: the true position with Gaussian noise per horizontal axis, heading kept (an
  // INS gives it far better than GNSS gives position); search radius 3 sigma.
  Pose3d T_map_sensor = truth_[q.frame];
  T_map_sensor.translation().x() += config_.gnss_sigma_m * gnss_rng_.normal();
  T_map_sensor.translation().y() += config_.gnss_sigma_m * gnss_rng_.normal();
  request.flags |= api::kFlagHasPrior;
  request.T_map_local_prior = T_map_sensor * q.T_odom_sensor.inverse();
  request.prior_radius_m = 3.0 * config_.gnss_sigma_m;
  return "gnss";
}

bool QueryPriors::update(const api::LocalizeReply& reply, const io::ReplayQuery& q) {
  return config_.track && tracker_.update(reply, q.odometer_m) == api::TrackUpdate::kRejected;
}

void PriorComparison::add(const api::LocalizeRequest& request, const api::LocalizeReply& reply,
                          const LocalizeFn& localize) {
  if (!(request.flags & api::kFlagHasPrior)) return;
  api::LocalizeRequest global = request;
  global.flags &= ~(api::kFlagHasPrior | api::kFlagPriorHeading);
  const api::LocalizeReply g = localize(global);
  auto match_ms = [](const api::ModuleTimingsMs& t) { return double(t.retrieve) + t.classify + t.verify; };
  prior_server_ms.push_back(reply.timings.server_total), prior_match_ms.push_back(match_ms(reply.timings));
  global_server_ms.push_back(g.timings.server_total), global_match_ms.push_back(match_ms(g.timings));
}

void PriorComparison::write_to(LocalizationRun& run) const {
  run.ab_prior_server_ms = distribution_of(prior_server_ms), run.ab_prior_match_ms = distribution_of(prior_match_ms);
  run.ab_global_server_ms = distribution_of(global_server_ms),
  run.ab_global_match_ms = distribution_of(global_match_ms);
}

}  // namespace eval
}  // namespace segmatch
