// Cold start (Localizer::recognize_place, place_recognition.h; beyond the paper): a query with
// no prior that segment matching refused, typically one sparse scan, is compared with the map's
// places; each of the most alike is a prior for tracking on the surface layer, whose gates
// (fitness, the query's segments, look-alikes beside the pose) decide. Private to the core.
#include "localizer_stages.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

namespace segmatch {

LocalizationResult Localizer::recognize_place(LocalizationResult refused, const PointCloud& cloud, const PointCloud& newest,
                                              const Eigen::Vector3f& sensor_position) const {
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
  const PlaceDescriptor query = describe_place(cloud.empty() ? newest : cloud, s, 0.0, c);
  const std::vector<PlaceCandidate> candidates = places->query(query, s);
  if (candidates.empty()) return unchanged("no place of the map resembles the scan");
  // The tracker's gates, with a cold start's segment floors and fitness (PlaceRecognitionConfig).
  LocalizerConfig gates = config_;
  gates.registration.min_support = c.min_support;
  gates.min_support = gates.min_support_with_prior = c.min_support;
  gates.track.min_matched_segments = gates.track.min_matched_segments_near_prior = c.min_matched_segments;
  gates.track.min_fitness = gates.search.min_fitness = c.min_fitness;
  gates.track.max_shifted_support = c.max_shifted_support;  // 0: off
  std::vector<LocalizationResult> passed;
  std::string first_reason;
  for (const PlaceCandidate& candidate : candidates) {
    const PosePrior prior{candidate.T_map_query, c.prior_radius_m, c.heading_tolerance_deg};
    LocalizationResult trial;
    trial.query = refused.query;
    trial.query_segments = trial.query.size();
    detail::track_on_surfaces(scans, targets_, centroids_, classifier_.get(), surfaces_.get(), gates, prior, sensor_position, trial);
    if (!trial.localized()) {
      if (first_reason.empty()) first_reason = trial.reason;  // the likeliest place's
      continue;
    }
    passed.push_back(std::move(trial));
  }
  if (passed.empty()) {
    char why[64];
    std::snprintf(why, sizeof(why), "%zu places tried (best distance %.2f)", candidates.size(), candidates.front().distance);
    return unchanged(std::string(why) + ", none tracked; the nearest: " + first_reason);
  }
  // The best fit answers unless a distinct place fits nearly as well (fitness_margin).
  std::stable_sort(passed.begin(), passed.end(),
                   [](const LocalizationResult& x, const LocalizationResult& y) { return x.refine_fitness > y.refine_fitness; });
  const Eigen::Vector3d best = passed.front().T_map_query * s;
  for (size_t i = 1; i < passed.size(); ++i) {
    const double apart_m = ((passed[i].T_map_query * s) - best).head<2>().norm();
    if (apart_m > config_.search.min_separation_m && passed[i].refine_fitness >= passed.front().refine_fitness - c.fitness_margin) {
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
