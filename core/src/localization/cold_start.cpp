// Cold start (Localizer::recognize_place, place_recognition.h; beyond the paper): a query with
// no prior that segment matching refused, typically one sparse scan, is compared with the map's
// places; each of the most alike is a prior for tracking on the surface layer, whose gates
// (fitness, the query's segments, look-alikes beside the pose) decide. Private to the core.
#include "localization/localizer_stages.h"

#include "segmatch/core/profile/input_profile.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

namespace segmatch {
namespace {

// What one view of the scan gave: the places that passed every gate, or why none did.
struct PlacesTried {
  std::vector<LocalizationResult> passed;
  std::string why;  // when none passed
};

// The places most like `query` (the scan's descriptor), each a prior for tracking `scans` on the
// surface layer with a cold start's gates.
PlacesTried try_places(const PlaceIndex& places, const PlaceDescriptor& query, const PointCloud& scans,
                       const Segments& targets, const CentroidIndex& centroids, const RandomForestMatcher* classifier,
                       const MapSurfaces* surfaces, const LocalizerConfig& gates, const Segments& query_segments,
                       const Eigen::Vector3f& sensor) {
  const PlaceRecognitionConfig& c = gates.places;
  PlacesTried out;
  const std::vector<PlaceCandidate> candidates = places.query(query, sensor.cast<double>());
  if (candidates.empty()) {
    out.why = "no place of the map resembles the scan";
    return out;
  }
  std::string first_reason;
  for (const PlaceCandidate& candidate : candidates) {
    const PosePrior prior{candidate.T_map_query, c.prior_radius_m, c.heading_tolerance_deg};
    LocalizationResult trial;
    trial.query = query_segments;
    trial.query_segments = trial.query.size();
    detail::track_on_surfaces(scans, targets, centroids, classifier, surfaces, gates, prior, sensor, trial);
    if (!trial.localized()) {
      if (first_reason.empty()) first_reason = trial.reason;  // the likeliest place's
      continue;
    }
    out.passed.push_back(std::move(trial));
  }
  char why[64];
  std::snprintf(why, sizeof(why), "%zu places tried (best distance %.2f)", candidates.size(),
                candidates.front().distance);
  out.why = std::string(why) + ", none tracked; the nearest: " + first_reason;
  return out;
}

}  // namespace

LocalizationResult Localizer::recognize_place(LocalizationResult refused, const PointCloud& cloud,
                                              const PointCloud& newest, const Eigen::Vector3f& sensor_position) const {
  const PlaceRecognitionConfig& c = config_.places;
  const auto start = std::chrono::steady_clock::now();
  // Its time counts as refinement, as tracking's does.
  auto add_time = [&start](ModuleTimings& t) {
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    t.refine_ms += ms;
    t.total_ms += ms;
  };
  auto unchanged = [&](const std::string& why) {
    refused.reason += " (place recognition: " + why + ")";
    add_time(refused.timings);
    return refused;
  };
  const PlaceIndex* places = c.enabled && surfaces_ ? this->places() : nullptr;
  if (!places || places->size() == 0) return refused;
  const Eigen::Vector3d s = sensor_position.cast<double>();
  const PointCloud& scans = newest.empty() ? cloud : newest;
  // The tracker's gates, with a cold start's segment floors and fitness (PlaceRecognitionConfig).
  LocalizerConfig gates = config_;
  gates.registration.min_support = c.min_support;
  gates.min_support = gates.min_support_with_prior = c.min_support;
  gates.track.min_matched_segments = gates.track.min_matched_segments_near_prior = c.min_matched_segments;
  gates.track.min_fitness = gates.search.min_fitness = c.min_fitness;
  gates.track.max_shifted_support = c.max_shifted_support;  // 0: off
  auto tried = [&](const PointCloud& view, const PlaceDescriptor& query) {
    return try_places(*places, query, view, targets_, centroids_, classifier_.get(), surfaces_.get(), gates,
                      refused.query, sensor_position);
  };
  PlacesTried found = tried(scans, describe_place(cloud.empty() ? newest : cloud, s, 0.0, c));
  // A second look when none passed and the scan reaches elevations the map's sensor never saw
  // (PlaceRecognitionConfig::map_elevation_*): kept to those it saw. Not the first look: a
  // handheld or pitched sensor's band moves with its tilt in the query frame.
  const ElevationBand shown = measure_elevations(scans, sensor_position);
  if (found.passed.empty() && (shown.min_deg < c.map_elevation_min_deg - c.elevation_excess_deg ||
                               shown.max_deg > c.map_elevation_max_deg + c.elevation_excess_deg)) {
    const double lo = c.map_elevation_min_deg - c.elevation_margin_deg,
                 hi = c.map_elevation_max_deg + c.elevation_margin_deg;
    const PointCloud kept = crop_elevation(scans, sensor_position, lo, hi);
    PlacesTried second = tried(
        kept, describe_place(cloud.empty() || &cloud == &scans ? kept : crop_elevation(cloud, sensor_position, lo, hi),
                             s, 0.0, c));
    second.why = found.why + "; kept to the map's elevations: " + second.why;
    found = std::move(second);
  }
  std::vector<LocalizationResult>& passed = found.passed;
  if (passed.empty()) return unchanged(found.why);
  // The best fit answers unless a distinct place fits nearly as well (fitness_margin).
  std::stable_sort(passed.begin(), passed.end(), [](const LocalizationResult& x, const LocalizationResult& y) {
    return x.refine_fitness > y.refine_fitness;
  });
  const Eigen::Vector3d best = passed.front().T_map_query * s;
  for (size_t i = 1; i < passed.size(); ++i) {
    const double apart_m = ((passed[i].T_map_query * s) - best).head<2>().norm();
    if (apart_m > config_.search.min_separation_m &&
        passed[i].refine_fitness >= passed.front().refine_fitness - c.fitness_margin) {
      char why[160];
      std::snprintf(why, sizeof(why), "ambiguous: the scan fits places %.1f m apart (fitness %.3f and %.3f)", apart_m,
                    passed.front().refine_fitness, passed[i].refine_fitness);
      refused = detail::refuse(std::move(refused), Refusal::kAmbiguous, why);
      return unchanged(std::to_string(passed.size()) + " places pass every gate");
    }
  }
  LocalizationResult r = std::move(passed.front());
  r.method = LocalizationMethod::kPlaces;
  r.timings = refused.timings;
  add_time(r.timings);
  return r;
}

}  // namespace segmatch
