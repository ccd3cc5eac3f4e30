// Tracking on the surface layer (Localizer::track, SurfaceTrackingConfig; beyond the paper):
// the vehicle's newest scans registered onto the map's surface layer around a tracker's prior,
// the pose checked by the query's segments as every registration is, and by where else along
// and across the street they would fit better. Private to the core.
#include "localization/localizer_stages.h"

#include "segmatch/core/localization/correlative_search.h"
#include "segmatch/core/localization/registration.h"
#include "segmatch/core/preprocess/preprocess.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace segmatch {
namespace detail {

namespace {

// The newest points registered onto the surface layer around the prior
// (SurfaceTrackingConfig): the fine stage alone from the prior, onto the layer within the reach
// of a pose that moves at most fine_first_m; both stages onto the wider disc a prior of this
// radius needs when that does not pass every gate.
RegistrationResult register_on_layer(const PointCloud& points, const MapSurfaces& surfaces,
                                     const LocalizerConfig& config, const PosePrior& prior, const Eigen::Vector3d& s,
                                     bool* near_prior) {
  *near_prior = false;
  const SurfaceTrackingConfig& c = config.track;
  const Eigen::Vector3d centre = prior.T_map_query * s;
  RegistrationConfig gates = config.registration;
  gates.window_m = c.window_m;
  gates.min_query_points = c.min_points;
  gates.min_fitness = c.min_fitness;
  const float max_rmse_m = std::max(config.max_refine_rmse_voxels * config.segmentation.voxel.leaf_m, c.leaf_m);
  auto registered = [&](const RegistrationConfig& g, double reach_m) {
    const PointCloud layer = surfaces.near(centre, reach_m);
    return register_to_map(points, layer, prior.T_map_query, s, prior.radius_m, prior.max_rotation_deg, max_rmse_m, g,
                           config.refine, config.covariance);
  };
  if (c.fine_first_m > 0.0f && prior.radius_m <= c.fine_first_max_radius_m) {
    RegistrationConfig fine_only = gates;
    fine_only.coarse_stage = false;
    // A point moves at most fine_first_m plus its lever on the turn; its neighbours for the
    // normal lie within twice the correspondence distance of it.
    const double reach_m = c.window_m * (1.0 + prior.max_rotation_deg * M_PI / 180.0) + c.fine_first_m +
                           3.0 * config.refine.max_correspondence_m;
    RegistrationResult fine = registered(fine_only, reach_m);
    if (fine.accepted() && (fine.T_map_query * s - centre).norm() <= c.fine_first_m) {
      *near_prior = true;
      return fine;
    }
  }
  return registered(gates, c.window_m + prior.radius_m + kWindowMarginM);
}

// The newest points (thinned) registered around one prior and checked; false with r's
// registration refusal and reason when a gate refuses.
bool track_from(const PointCloud& points, const Segments& targets, const CentroidIndex& centroids,
                const RandomForestMatcher* classifier, const MapSurfaces& surfaces, const LocalizerConfig& config,
                const PosePrior& prior, const Eigen::Vector3d& s, double ambiguity_range_m, LocalizationResult& r,
                RegistrationResult& reg) {
  const SurfaceTrackingConfig& c = config.track;
  bool near_prior = false;
  reg = register_on_layer(points, surfaces, config, prior, s, &near_prior);
  r.registration_refusal = reg.refusal;
  r.registration_reason = reg.reason;
  r.refine_fitness = reg.fitness;
  r.refine_rmse_m = reg.rmse_m;
  r.T_map_query = reg.T_map_query;
  if (!reg.accepted()) return false;
  // The fewer matched pairs of a pose the prediction or a dense layout of objects witnesses
  // (SurfaceTrackingConfig::min_matched_segments_near_prior) first; the full count otherwise.
  const int fewer = std::min(c.min_matched_segments_near_prior, c.min_matched_segments);
  if (!well_supported(targets, centroids, classifier, config, reg.T_map_query, fewer, r)) return false;
  const bool dense =
      c.min_support_for_fewer_matched > 0 && r.support >= static_cast<size_t>(c.min_support_for_fewer_matched);
  if (!near_prior && !dense && r.inliers.size() < static_cast<size_t>(c.min_matched_segments)) {
    r.registration_refusal = RegistrationRefusal::kLowSupport;
    r.registration_reason = std::to_string(r.support) +
                            " query segments land on map segments under the registered pose, " +
                            std::to_string(r.inliers.size()) + " of them matched (at least " +
                            std::to_string(c.min_matched_segments) + " matched, or " + std::to_string(fewer) +
                            " from " + std::to_string(c.min_support_for_fewer_matched) + " landing)";
    return false;
  }
  return unambiguous_along_street(reg, centroids, config, ambiguity_range_m, r);
}

// A prior too wide for registration (a GNSS fix, a tracker long without one): the correlative
// search (correlative_search.h) of the newest points over the surface layer, both without their
// ground (it is everywhere, top-down), gives the best distinct peaks; tracking from each, with
// the wide prior's fitness floor (CorrelativeSearchConfig::min_fitness) over every tracking gate.
// One passing answers; two at distinct places are an ambiguity.
bool track_over_wide_prior(const PointCloud& points, const Segments& targets, const CentroidIndex& centroids,
                           const RandomForestMatcher* classifier, const MapSurfaces& surfaces,
                           const LocalizerConfig& config, const PosePrior& prior, const Eigen::Vector3d& s,
                           LocalizationResult& r, RegistrationResult& answer) {
  const CorrelativeSearchConfig& search = config.search;
  const Eigen::Vector3d centre = prior.T_map_query * s;
  const double reach_m = config.track.window_m + prior.radius_m + kWindowMarginM;
  const PointCloud layer = surfaces.near(centre, reach_m);
  const PointCloud map_objects = remove_ground(layer, config.segmentation.ground, centre.cast<float>());
  const PointCloud query_objects = remove_ground(points, config.segmentation.ground, s.cast<float>());
  const std::vector<SearchCandidate> peaks =
      correlative_search(query_objects, map_objects, prior.T_map_query, s, prior.radius_m, prior.max_rotation_deg,
                         config.track.window_m, search);
  if (peaks.empty()) {
    r.registration_refusal = RegistrationRefusal::kFewPoints;
    r.registration_reason = "no newest or layer points above the ground to search the prior with";
    return false;
  }
  // A look-alike anywhere in the disc may be where the scans fit: every pose the prior allows,
  // and the truth just beyond it, is tested for a better support (a wrong 20 m prior on the
  // simulated city was otherwise answered 30.5 m off, 3 matched, support 17).
  std::vector<RegistrationResult> passed;
  LocalizationResult first = r, last = r;
  for (const SearchCandidate& peak : peaks) {
    // Each peak is a prior as wide as registration takes: along a street of facades the 1 m
    // grid's peak can lie metres and degrees from where the scans fit (on riverside02 up to
    // 5.6 m and 2.1 degrees). Where it settles, every gate decides, and the other peaks' answers
    // with it.
    const PosePrior at{peak.T_map_query, config.registration.max_prior_radius_m, prior.max_rotation_deg};
    LocalizationResult trial = r;
    RegistrationResult reg;
    const bool ok = track_from(points, targets, centroids, classifier, surfaces, config, at, s,
                               ambiguity_range_m(config, prior), trial, reg) &&
                    within_wide_prior(reg, prior, s, search, trial.registration_refusal, trial.registration_reason);
    if (!ok) {
      if (passed.empty()) last = std::move(trial);
      continue;
    }
    if (!distinct_from(passed, reg, s, search.min_separation_m)) continue;
    if (passed.empty()) first = std::move(trial);
    passed.push_back(reg);
  }
  if (passed.size() == 1) {
    r = std::move(first);
    answer = passed.front();
    return true;
  }
  r = std::move(last);
  if (passed.size() > 1) {
    r.registration_refusal = RegistrationRefusal::kAmbiguous;
    r.registration_reason = std::to_string(passed.size()) + " distinct poses within the prior pass tracking";
  } else {
    r.registration_reason =
        "none of " + std::to_string(peaks.size()) + " search peaks tracked: " + r.registration_reason;
  }
  return false;
}

}  // namespace

void track_on_surfaces(const PointCloud& newest, const Segments& targets, const CentroidIndex& centroids,
                       const RandomForestMatcher* classifier, const MapSurfaces* surfaces,
                       const LocalizerConfig& config, const PosePrior& prior, const Eigen::Vector3f& sensor,
                       LocalizationResult& r) {
  const SurfaceTrackingConfig& c = config.track;
  auto lost = [&r](std::string why) {
    r = refuse(std::move(r), Refusal::kTrackingLost, "tracking on the surface layer: " + why);
    r.registration_reason.clear();  // it is the reason now; the typed registration_refusal stays
  };
  if (!c.enabled) return lost("off in this map's parameters (track.enabled)");
  if (!surfaces) return lost("the map has no surface layer");
  if (prior.radius_m > max_tracked_radius_m(config))
    return lost("the prior's radius " + std::to_string(prior.radius_m) +
                " m is wider than the widest tracked (max_tracked_radius_m)");
  const Eigen::Vector3d s = sensor.cast<double>();
  VoxelGridConfig thin;
  thin.leaf_m = c.leaf_m;
  thin.min_points_per_voxel = 1;
  const PointCloud points = voxel_filter(crop_cylinder(newest, s, c.window_m), thin);
  if (points.size() < static_cast<size_t>(c.min_points))
    return lost(std::to_string(points.size()) + " newest points near the sensor (at least " +
                std::to_string(c.min_points) + ")");
  RegistrationResult reg;
  const bool tracked =
      prior.radius_m > config.registration.max_prior_radius_m
          ? track_over_wide_prior(points, targets, centroids, classifier, *surfaces, config, prior, s, r, reg)
          : track_from(points, targets, centroids, classifier, *surfaces, config, prior, s,
                       ambiguity_range_m(config, prior), r, reg);
  if (!tracked) return lost(r.registration_reason);
  r.window_points = points.size();
  localized_by(reg, r, LocalizationMethod::kSurfaces);
}

}  // namespace detail
}  // namespace segmatch
