#include "localization/localizer_stages.h"

#include "segmatch/core/localization/correlative_search.h"
#include "segmatch/core/localization/registration.h"
#include "segmatch/core/preprocess/preprocess.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace segmatch {
namespace detail {

LocalizationResult refuse(LocalizationResult r, Refusal refusal, std::string why) {
  r.status = LocalizationStatus::kNotLocalized;
  r.refusal = refusal;
  r.reason = std::move(why);
  r.covariance.setZero();  // a refused pose has none
  return r;
}

// The map segments whose centroids lie within radius_m of center, horizontally.
std::vector<int> targets_within_disc(const Segments& targets, const Eigen::Vector3d& center, double radius_m) {
  std::vector<int> out;
  for (size_t t = 0; t < targets.size(); ++t)
    if ((targets[t].centroid.cast<double>() - center).head<2>().norm() <= radius_m) out.push_back(static_cast<int>(t));
  return out;
}

// Points of the segments on one side of the matches, for the refinement: every stride-th point
// of each segment (segment_point_stride).
// With `source`, a target's points come from there (the same points, in the same order).
PointCloud gather(const Segments& segments, const Matches& inliers, bool query_side, size_t stride,
                  const TargetPoints* source) {
  PointCloud out;
  std::vector<bool> taken(segments.size(), false);
  for (const Match& m : inliers) {
    const int i = query_side ? m.query : m.target;
    if (taken[i]) continue;
    taken[i] = true;
    if (source) {
      source->append(static_cast<size_t>(i), &out);
      continue;
    }
    const PointCloud& points = segments[i].points;
    for (size_t k = 0; k < points.size(); k += stride) out.push_back(points[k]);
  }
  return out;
}

namespace {

// Every query segment's points (every stride-th of each).
PointCloud all_query_points(const Segments& query, size_t stride) {
  Matches all;
  for (size_t i = 0; i < query.size(); ++i) all.push_back({static_cast<int>(i), 0});
  return gather(query, all, true, stride);
}

// The points of every map segment whose centroid lies within radius_m of center, horizontally.
PointCloud map_points_near(const Segments& targets, const TargetPoints* source, const Eigen::Vector3d& center,
                           double radius_m) {
  Matches near;
  for (int t : targets_within_disc(targets, center, radius_m)) near.push_back({0, t});
  return gather(targets, near, false, 1, source);
}

}  // namespace

// The recent window's points (RefineConfig::recent_window_m): every query segment's points
// near the sensor, and every map segment's near where the pose puts the sensor (a margin for
// segments that straddle the window's edge). The window has fewer matched segments than the
// whole cloud, so it takes all it has, not only the supporting ones.
WindowPoints window_points(const Segments& query, const Segments& targets, const TargetPoints* source,
                           const Eigen::Vector3d& sensor, const Pose3d& T_map_query, size_t stride, float window_m) {
  return {crop_cylinder(all_query_points(query, stride), sensor, window_m),
          map_points_near(targets, source, T_map_query * sensor, window_m + kWindowMarginM)};
}

// The sensor's pose now: the window refined alone from the whole cloud's pose. The odometry
// that built the cloud drifted between its oldest scans and the sensor; near the sensor that
// drift is small.
void refine_recent_window(const WindowPoints& points, const Eigen::Vector3f& sensor, float min_fitness,
                          const RefineConfig& config, const CovarianceConfig& covariance, LocalizationResult& r) {
  const Eigen::Vector3d s = sensor.cast<double>();
  const PointCloud& recent = points.query;
  if (recent.size() < static_cast<size_t>(config.min_recent_points)) return;
  const RefineResult window = refine_alignment(recent, points.targets, r.T_map_query, config, r.T_map_query * s);
  if (window.fitness < min_fitness) return;
  r.covariance = pose_covariance(window, covariance);
  r.window_points = recent.size();
  r.window_warp_m = static_cast<float>((window.T_target_query * s - r.T_map_query * s).norm());
  const Eigen::AngleAxisd turn(window.T_target_query.linear() * r.T_map_query.linear().transpose());
  r.window_warp_deg = static_cast<float>(std::abs(turn.angle()) * 180.0 / M_PI);
  r.T_map_query = window.T_target_query;
}

void describe_pending(Segments& query, const Matches* pairs, const DescriptorConfig& config, const Deadline& deadline) {
  auto pending = [](const Segment& s) { return !s.has_eigen && !s.has_esf; };
  auto describe = [&](size_t i) {
    Segments one(1);
    one.front() = std::move(query[i]);
    describe_segments(one, config);
    query[i] = std::move(one.front());
  };
  if (pairs) {
    for (const Match& m : *pairs)
      if (m.query >= 0 && static_cast<size_t>(m.query) < query.size() && pending(query[m.query])) describe(m.query);
    return;
  }
  for (size_t i = 0; i < query.size() && !deadline.passed(); ++i)
    if (pending(query[i])) describe(i);
}

bool well_supported(const Segments& targets, const CentroidIndex& centroids, const RandomForestMatcher* classifier,
                    const LocalizerConfig& config, const Pose3d& T_map_query, int min_matched_segments,
                    LocalizationResult& r) {
  const Support support = support_of(r.query, centroids, T_map_query, config.support_radius_m);
  r.support = support.count();
  describe_pending(r.query, &support.pairs, config.segmentation.descriptors);
  r.inliers = filter_matches(r.query, targets, support.pairs, config.matcher, classifier);
  const int min_support = config.registration.min_support;
  if (r.support >= static_cast<size_t>(min_support) && r.inliers.size() >= static_cast<size_t>(min_matched_segments))
    return true;
  r.registration_refusal = RegistrationRefusal::kLowSupport;
  r.registration_reason = std::to_string(r.support) +
                          " query segments land on map segments under the registered pose, " +
                          std::to_string(r.inliers.size()) + " of them matched (at least " +
                          std::to_string(min_support) + " and " + std::to_string(min_matched_segments) + ")";
  return false;
}

void localized_by(const RegistrationResult& reg, LocalizationResult& r, LocalizationMethod method) {
  r.registration_refusal = RegistrationRefusal::kNone;
  r.registration_reason.clear();
  r.refine_fitness = reg.fitness;
  r.refine_rmse_m = reg.rmse_m;
  r.status = LocalizationStatus::kLocalized;
  r.method = method;
  r.T_map_query = reg.T_map_query;
  r.covariance = reg.covariance;
  r.confidence = reg.fitness;
}

bool within_wide_prior(const RegistrationResult& reg, const PosePrior& prior, const Eigen::Vector3d& s,
                       const CorrelativeSearchConfig& search, RegistrationRefusal& refusal, std::string& reason) {
  const double moved_m = (reg.T_map_query * s - prior.T_map_query * s).norm();
  const double turned_deg =
      Eigen::AngleAxisd(reg.T_map_query.linear() * prior.T_map_query.linear().transpose()).angle() * 180.0 / M_PI;
  if (moved_m > prior.radius_m || turned_deg > prior.max_rotation_deg) {
    refusal = RegistrationRefusal::kOutsidePrior;
    reason = "registered outside the prior";
    return false;
  }
  if (reg.fitness < search.min_fitness) {
    refusal = RegistrationRefusal::kLowFitness;
    reason = "registration fitness " + std::to_string(reg.fitness) + " below the wide prior's " +
             std::to_string(search.min_fitness);
    return false;
  }
  return true;
}

namespace {

struct ShiftedSupport {
  size_t support = 0;
  double offset_m = 0.0;
  bool along = true;
};

// The best support of the query segments under the pose shifted horizontally along `along` and
// across it, by 1.5 m to range_m (0.5 m steps, a half support radius).
ShiftedSupport best_shifted_support(const Segments& query, const CentroidIndex& centroids,
                                    const LocalizerConfig& config, const Pose3d& T_map_query, Eigen::Vector3d along,
                                    double range_m) {
  along.z() = 0.0;
  if (along.norm() < 1e-6) along = Eigen::Vector3d::UnitX();
  along.normalize();
  const Eigen::Vector3d across(-along.y(), along.x(), 0.0);
  ShiftedSupport best;
  for (const Eigen::Vector3d* axis : {static_cast<const Eigen::Vector3d*>(&along), &across})
    for (double d = 1.5; d <= range_m + 1e-9; d += 0.5)
      for (double sign : {-1.0, 1.0}) {
        Pose3d shifted = T_map_query;
        shifted.translation() += sign * d * *axis;
        const size_t n = support_of(query, centroids, shifted, config.support_radius_m).count();
        if (n > best.support) best = {n, sign * d, axis == &along};
      }
  return best;
}

}  // namespace

std::string look_alike_beside(const Pose3d& T_map_query, const Eigen::Vector3d& along, const CentroidIndex& centroids,
                              const LocalizerConfig& config, double range_m, const LocalizationResult& r) {
  if (!(config.track.max_shifted_support > 0.0f)) return {};  // off (a cold start's gates: PlaceRecognitionConfig)
  const ShiftedSupport shifted = best_shifted_support(r.query, centroids, config, T_map_query, along, range_m);
  if (static_cast<float>(shifted.support) < config.track.max_shifted_support * static_cast<float>(r.support)) return {};
  char why[200];
  std::snprintf(why, sizeof(why),
                "the pose %.1f m away (%s the street) has %zu supporting segments, the chosen one %zu: "
                "the objects fit elsewhere as well or better",
                shifted.offset_m, shifted.along ? "along" : "across", shifted.support, r.support);
  return why;
}

bool unambiguous_along_street(const RegistrationResult& reg, const CentroidIndex& centroids,
                              const LocalizerConfig& config, double range_m, LocalizationResult& r) {
  std::string why = look_alike_beside(reg.T_map_query, reg.weakest_axis, centroids, config, range_m, r);
  if (why.empty()) return true;
  r.registration_refusal = RegistrationRefusal::kAmbiguous;
  r.registration_reason = std::move(why);
  return false;
}

double ambiguity_range_m(const LocalizerConfig& config, const PosePrior& prior) {
  return std::max<double>(config.track.ambiguity_range_m, 2.0 * prior.radius_m);
}

bool distinct_from(const std::vector<RegistrationResult>& passed, const RegistrationResult& reg,
                   const Eigen::Vector3d& s, double min_separation_m) {
  for (const RegistrationResult& p : passed)
    if ((p.T_map_query * s - reg.T_map_query * s).norm() < min_separation_m) return false;
  return true;
}

namespace {

// Over a wide prior the support must also reach the localizer's own floors, with and without a
// prior, whichever is higher (CorrelativeSearchConfig).
bool supported_globally(const LocalizerConfig& config, LocalizationResult& r) {
  const int floor = std::max({config.min_support, config.min_support_with_prior, config.registration.min_support});
  if (r.support >= static_cast<size_t>(floor)) return true;
  r.registration_refusal = RegistrationRefusal::kLowSupport;
  r.registration_reason =
      std::to_string(r.support) +
      " query segments land on map segments under the registered pose (over a wide prior at least " +
      std::to_string(floor) + ")";
  return false;
}

// A prior too wide for ICP (CorrelativeSearchConfig): the correlative search's best distinct
// peaks are registered each from its own pose, with every gate of a narrow prior, and must stay
// within the wide prior. One passing answers; two passing at distinct places is an ambiguity
// (a street of look-alikes), refused.
void register_over_wide_prior(const Segments& targets, const TargetPoints* source, const CentroidIndex& centroids,
                              const RandomForestMatcher* classifier, const LocalizerConfig& config,
                              const PosePrior& prior, const Eigen::Vector3d& s, LocalizationResult& r) {
  const CorrelativeSearchConfig& search = config.search;
  const size_t stride = segment_point_stride(r.query, static_cast<size_t>(config.refine.max_segment_points));
  const PointCloud query = all_query_points(r.query, stride);
  const Eigen::Vector3d centre = prior.T_map_query * s;
  const PointCloud map =
      map_points_near(targets, source, centre, config.registration.window_m + prior.radius_m + kWindowMarginM);
  const std::vector<SearchCandidate> peaks = correlative_search(
      query, map, prior.T_map_query, s, prior.radius_m, prior.max_rotation_deg, config.registration.window_m, search);
  const float max_rmse_m = config.max_refine_rmse_voxels * config.segmentation.voxel.leaf_m;
  // A peak is within a cell and a heading step of a minimum: the registration from it may move
  // that far and a little more, no farther.
  const double peak_radius_m = 2.0 * search.resolution_m, peak_turn_deg = 2.0 * search.angle_step_deg;
  std::vector<RegistrationResult> passed;
  LocalizationResult last = r;
  for (const SearchCandidate& peak : peaks) {
    LocalizationResult trial = r;
    const Eigen::Vector3d at = peak.T_map_query * s;
    RegistrationResult reg = register_to_map(
        query, crop_cylinder(map, at, config.registration.window_m + kWindowMarginM), peak.T_map_query, s,
        peak_radius_m, peak_turn_deg, max_rmse_m, config.registration, config.refine, config.covariance);
    if (reg.accepted()) within_wide_prior(reg, prior, s, search, reg.refusal, reg.reason);
    trial.registration_refusal = reg.refusal;
    trial.registration_reason = reg.reason;
    if (reg.accepted() &&
        well_supported(targets, centroids, classifier, config, reg.T_map_query,
                       config.registration.min_matched_segments, trial) &&
        supported_globally(config, trial) &&
        unambiguous_along_street(reg, centroids, config, ambiguity_range_m(config, prior), trial)) {
      if (distinct_from(passed, reg, s, search.min_separation_m)) passed.push_back(reg);
      if (passed.size() == 1) last = trial;  // keep the first answer's support and inliers
      continue;
    }
    if (passed.empty()) last = trial;
  }
  r = last;
  if (passed.size() == 1) return localized_by(passed.front(), r);
  if (passed.size() > 1) {
    r.status = LocalizationStatus::kNotLocalized;
    r.registration_refusal = RegistrationRefusal::kAmbiguous;
    r.registration_reason = std::to_string(passed.size()) + " distinct poses within the prior pass registration";
    return;
  }
  if (peaks.empty()) {
    r.registration_refusal = RegistrationRefusal::kFewPoints;
    r.registration_reason = "no query or map points to search the prior with";
    return;
  }
  r.registration_reason =
      "none of " + std::to_string(peaks.size()) + " search peaks registered: " + r.registration_reason;
}

}  // namespace

// Tracking by registration (registration.h): every query segment's points near the sensor onto
// the map segments' near where the prior puts it. Localized, or the reason it did not answer.
void register_near_prior(const Segments& targets, const TargetPoints* source, const CentroidIndex& centroids,
                         const RandomForestMatcher* classifier, const LocalizerConfig& config, const PosePrior& prior,
                         const Eigen::Vector3f& sensor, LocalizationResult& r) {
  const Eigen::Vector3d s = sensor.cast<double>();
  const double reach = config.registration.window_m + prior.radius_m + kWindowMarginM;
  const size_t stride = segment_point_stride(r.query, static_cast<size_t>(config.refine.max_segment_points));
  const float max_rmse_m = config.max_refine_rmse_voxels * config.segmentation.voxel.leaf_m;
  const bool wide = prior.radius_m > config.registration.max_prior_radius_m;
  if (wide && config.search.enabled && prior.radius_m <= config.search.max_radius_m)
    return register_over_wide_prior(targets, source, centroids, classifier, config, prior, s, r);
  // A prior too wide to start from is refused before any point is gathered (register_to_map
  // checks the radius first and says why).
  const RegistrationResult reg = register_to_map(
      wide ? PointCloud{} : all_query_points(r.query, stride),
      wide ? PointCloud{} : map_points_near(targets, source, prior.T_map_query * s, reach), prior.T_map_query, s,
      prior.radius_m, prior.max_rotation_deg, max_rmse_m, config.registration, config.refine, config.covariance);
  r.registration_refusal = reg.refusal;
  r.registration_reason = reg.reason;
  r.refine_fitness = reg.fitness;
  r.refine_rmse_m = reg.rmse_m;
  if (!reg.accepted() ||
      !well_supported(targets, centroids, classifier, config, reg.T_map_query, config.registration.min_matched_segments,
                      r) ||
      !unambiguous_along_street(reg, centroids, config, ambiguity_range_m(config, prior), r))
    return;
  localized_by(reg, r);
}

// The newest scans are raw points, ground included. Onto the map's surface layer they register
// whole: the ground holds height, roll and pitch. Without a layer the map holds segments only,
// and ground points near a segment's foot would pull the pose down onto it: ground goes first.
void refine_to_newest(const PointCloud& newest, const Segments& targets, const TargetPoints* source,
                      const MapSurfaces* surfaces, const LocalizerConfig& config, const Eigen::Vector3f& sensor,
                      LocalizationResult& r) {
  const NewestScansConfig& c = config.newest;
  const Eigen::Vector3d s = sensor.cast<double>();
  VoxelGridConfig thin;
  thin.leaf_m = c.leaf_m;
  thin.min_points_per_voxel = 1;
  PointCloud points = voxel_filter(crop_cylinder(newest, s, c.window_m), thin);
  if (!surfaces) points = remove_ground(points, config.segmentation.ground, sensor);
  if (points.size() < static_cast<size_t>(c.min_points)) {
    r.newest_refusal = RegistrationRefusal::kFewPoints;
    r.newest_reason = std::to_string(points.size()) + " newest points near the sensor (at least " +
                      std::to_string(c.min_points) + ")";
    return;
  }
  const Eigen::Vector3d centre = r.T_map_query * s;
  const double reach = c.window_m + kWindowMarginM;
  const PointCloud map = surfaces ? surfaces->near(centre, reach) : map_points_near(targets, source, centre, reach);
  RegistrationConfig settle = config.registration;  // one stage at the fine distance: the start is an answer
  settle.window_m = c.window_m;
  settle.coarse_correspondence_m = config.refine.max_correspondence_m;
  settle.min_query_points = c.min_points;
  settle.min_fitness = c.min_fitness;
  const float max_rmse_m = config.max_refine_rmse_voxels * config.segmentation.voxel.leaf_m;
  const RegistrationResult now =
      register_to_map(points, map, r.T_map_query, s, c.max_shift_m, c.max_turn_deg, std::max(max_rmse_m, c.leaf_m),
                      settle, config.refine, config.covariance);
  r.newest_refusal = now.refusal;
  r.newest_reason = now.reason;
  // Enough newest points were given (above), so too few points here means no layer near the
  // sensor; a registration that ended off the layer (low fitness, whether it settled or was
  // still being dragged) found no place where they lie on it.
  const bool off_map =
      now.refusal == RegistrationRefusal::kFewPoints || (!now.accepted() && now.fitness < c.min_fitness);
  if (surfaces && c.refuse_off_map && off_map) {
    char fit[96];
    std::snprintf(fit, sizeof(fit), "fitness %.2f, at least %.2f", now.fitness, c.min_fitness);
    r = refuse(std::move(r), Refusal::kOffMap,
               std::string("the vehicle's newest scans do not lie on the map's surfaces at the answer (") +
                   (now.refusal == RegistrationRefusal::kFewPoints ? now.reason : fit) +
                   "): the sensor sees what the map never saw");
    return;
  }
  // They lie on the layer, but settle farther from the answer than max_shift_m or turned past
  // max_turn_deg: the sensor's own view puts it elsewhere, and the answer is wrong or warped
  // beyond what the window explains.
  if (surfaces && c.refuse_off_map && now.refusal == RegistrationRefusal::kOutsidePrior) {
    r = refuse(std::move(r), Refusal::kNewestScansDisagree,
               "the vehicle's newest scans fit the map away from the answer (" + now.reason + ")");
    return;
  }
  if (!now.accepted()) return;
  r.window_points = points.size();
  r.window_warp_m = static_cast<float>((now.T_map_query * s - centre).norm());
  const Eigen::AngleAxisd turn(now.T_map_query.linear() * r.T_map_query.linear().transpose());
  r.window_warp_deg = static_cast<float>(std::abs(turn.angle()) * 180.0 / M_PI);
  r.T_map_query = now.T_map_query;
  r.covariance = now.covariance;
}

}  // namespace detail
}  // namespace segmatch
