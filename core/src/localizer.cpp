#include "segmatch/core/localizer.h"

#include "localizer_stages.h"

#include <chrono>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace segmatch {
namespace {

using detail::gather;
using detail::rank_by_support;
using detail::Ranked;
using detail::spread_axis;
using detail::targets_near_prior;
using detail::within_prior;

class Stopwatch {
 public:
  // Milliseconds since the last call (or construction).
  double lap() {
    const auto now = std::chrono::steady_clock::now();
    const double ms = std::chrono::duration<double, std::milli>(now - last_).count();
    last_ = now;
    return ms;
  }

 private:
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

using detail::refuse;

// The floors in force: with a prior, the *_with_prior ones that are set (>= 0).
struct Floors {
  int min_support;
  float min_fitness, min_confidence;
};
Floors floors_of(const LocalizerConfig& c, bool prior) {
  auto pick = [prior](auto with_prior, auto without) { return prior && with_prior >= 0 ? with_prior : without; };
  return {pick(c.min_support_with_prior, c.min_support), pick(c.min_refine_fitness_with_prior, c.min_refine_fitness),
          pick(c.min_confidence_with_prior, c.min_confidence)};
}

// Confidence in 0..1: grows with the number of query segments that agree with the pose
// beyond the minimum (each extra independent agreement makes a coincidence much less
// likely) and is scaled by how well the surfaces agree after refinement.
float confidence_of(size_t support, int min_support, float fitness) {
  const double extra = static_cast<double>(support) - min_support + 1.0;
  return static_cast<float>((1.0 - std::exp(-extra / 3.0)) * fitness);
}

LocalizationResult stopped(LocalizationResult r, const char* when) {
  return refuse(std::move(r), Refusal::kDeadlinePassed, std::string("the query's deadline passed ") + when);
}

void check_prior(const PosePrior* prior) {
  if (prior && !(prior->radius_m > 0.0 && std::isfinite(prior->radius_m) && prior->T_map_query.matrix().allFinite() &&
                 prior->max_rotation_deg >= 0.0 && std::isfinite(prior->max_rotation_deg)))
    throw std::invalid_argument("PosePrior needs a finite pose, a finite radius_m > 0 and max_rotation_deg >= 0");
}

}  // namespace

size_t segment_point_stride(const Segments& segments, size_t max_points) {
  size_t total = 0;
  for (const Segment& s : segments) total += s.points.size();
  if (max_points == 0 || total <= max_points) return 1;
  return (total + max_points - 1) / max_points;
}

void thin_segment_points(Segments& segments, size_t max_points) {
  const size_t stride = segment_point_stride(segments, max_points);
  if (stride == 1) return;
  for (Segment& s : segments) {
    size_t kept = 0;
    for (size_t i = 0; i < s.points.size(); i += stride) s.points[kept++] = s.points[i];
    s.points.resize(kept);
  }
}

PointCloud crop_cylinder(const PointCloud& cloud, const Eigen::Vector3d& center, double radius_m) {
  const double r2 = radius_m * radius_m;
  PointCloud out;
  out.reserve(cloud.size());
  for (const Point& p : cloud) {
    const double dx = p.x - center.x(), dy = p.y - center.y();
    if (dx * dx + dy * dy <= r2) out.push_back(p);
  }
  return out;
}

PointCloud crop_elevation(const PointCloud& cloud, const Eigen::Vector3f& sensor, double min_deg, double max_deg) {
  // Compared as tangents: elevation e lies in [min, max] iff tan(min) * d <= dz <= tan(max) * d.
  const double lo = std::tan(std::max(min_deg, -89.9) * M_PI / 180.0), hi = std::tan(std::min(max_deg, 89.9) * M_PI / 180.0);
  PointCloud out;
  out.reserve(cloud.size());
  for (const Point& p : cloud) {
    const double d = std::hypot(double(p.x) - sensor.x(), double(p.y) - sensor.y()), dz = double(p.z) - sensor.z();
    if (dz >= lo * d && dz <= hi * d) out.push_back(p);
  }
  return out;
}

const char* to_string(LocalizationStatus status) {
  return status == LocalizationStatus::kLocalized ? "localized" : "not_localized";
}

const char* to_string(LocalizationMethod method) {
  switch (method) {
    case LocalizationMethod::kRegistration: return "registration";
    case LocalizationMethod::kSurfaces: return "surfaces";
    case LocalizationMethod::kPlaces: return "places";
    case LocalizationMethod::kSegments: break;
  }
  return "segments";
}

const char* to_string(Refusal refusal) {
  switch (refusal) {
    case Refusal::kNone: return "none";
    case Refusal::kEmptyMap: return "empty_map";
    case Refusal::kTooFewSegments: return "too_few_segments";
    case Refusal::kNoConsistentMatches: return "no_consistent_matches";
    case Refusal::kOutsidePrior: return "outside_prior";
    case Refusal::kLowSupport: return "low_support";
    case Refusal::kAmbiguous: return "ambiguous";
    case Refusal::kSurfacesDisagree: return "surfaces_disagree";
    case Refusal::kLowConfidence: return "low_confidence";
    case Refusal::kDeadlinePassed: return "deadline_passed";
    case Refusal::kOffMap: return "off_map";
    case Refusal::kNewestScansDisagree: return "newest_scans_disagree";
    case Refusal::kTrackingLost: return "tracking_lost";
  }
  return "unknown";
}

void SegmentationConfig::validate() const {
  voxel.validate();
  ground.validate();
  segmenter.validate();
  descriptors.validate();
}

void LocalizerConfig::validate() const {
  segmentation.validate();
  retrieval.validate();
  matcher.validate();
  verification.validate();
  refine.validate();
  registration.validate();
  covariance.validate();
  newest.validate();
  search.validate();
  track.validate();
  places.validate();
  if (!(min_refine_fitness >= 0.0f && min_refine_fitness <= 1.0f))
    throw std::invalid_argument("min_refine_fitness must be in 0..1");
  if (!(max_refine_rmse_voxels >= 0.0f) || !std::isfinite(max_refine_rmse_voxels))
    throw std::invalid_argument("max_refine_rmse_voxels must be finite and >= 0 (0: off)");
  if (!(min_confidence >= 0.0f && min_confidence <= 1.0f))
    throw std::invalid_argument("min_confidence must be in 0..1");
  if (!(support_radius_m > 0.0f) || !std::isfinite(support_radius_m))
    throw std::invalid_argument("support_radius_m must be finite and > 0");
  if (min_support < verification.min_inliers)
    throw std::invalid_argument("min_support must be at least verification.min_inliers");
  if (min_support_with_prior >= 0 && min_support_with_prior < verification.min_inliers)
    throw std::invalid_argument("min_support_with_prior must be at least verification.min_inliers (or negative: unused)");
  if (!(min_refine_fitness_with_prior <= 1.0f))
    throw std::invalid_argument("min_refine_fitness_with_prior must be <= 1 (negative: unused)");
  if (!(min_confidence_with_prior <= 1.0f))
    throw std::invalid_argument("min_confidence_with_prior must be <= 1 (negative: unused)");
  if (!(max_ambiguity > 0.0f && max_ambiguity <= 1.0f)) throw std::invalid_argument("max_ambiguity must be in (0, 1]");
  if (matcher.use_shapes && !segmentation.descriptors.compute_esf)
    throw std::invalid_argument("matcher.use_shapes needs segmentation.descriptors.compute_esf");
}

namespace {

// Segmentation (voxels, ground, clusters), then the description unless `describe` is false: the
// tracking path describes only the segments it checks (detail::describe_pending).
Segments segments_of_voxels(const PointCloud& voxels, const Eigen::Vector3f& sensor_position, const SegmentationConfig& config,
                            const std::vector<uint32_t>* voxel_labels, ModuleTimings& t, const Deadline& deadline, bool describe) {
  Stopwatch clock;
  std::vector<uint32_t> foreground_labels;
  const PointCloud foreground = remove_ground(voxels, config.ground, sensor_position, voxel_labels,
                                              voxel_labels ? &foreground_labels : nullptr);
  t.ground_ms = clock.lap();
  if (deadline.passed()) return {};
  Segments segments = segment_cloud(foreground, config.segmenter, voxel_labels ? &foreground_labels : nullptr);
  t.segment_ms = clock.lap();
  if (deadline.passed()) return {};
  if (describe) describe_segments(segments, config.descriptors, deadline);
  t.describe_ms = clock.lap();
  return segments;
}

Segments segments_of_cloud(const PointCloud& cloud, const Eigen::Vector3f& sensor_position, const SegmentationConfig& config,
                           const std::vector<uint32_t>* labels, ModuleTimings& t, const Deadline& deadline, bool describe) {
  Stopwatch clock;
  std::vector<uint32_t> voxel_labels;
  const PointCloud voxels = voxel_filter(cloud, config.voxel, labels, labels ? &voxel_labels : nullptr);
  t.voxel_ms = clock.lap();
  if (deadline.passed()) return {};
  return segments_of_voxels(voxels, sensor_position, config, labels ? &voxel_labels : nullptr, t, deadline, describe);
}

}  // namespace

Segments extract_segments(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                          const SegmentationConfig& config, const std::vector<uint32_t>* labels,
                          ModuleTimings* timings, const Deadline& deadline) {
  ModuleTimings local;
  return segments_of_cloud(cloud, sensor_position, config, labels, timings ? *timings : local, deadline, true);
}

Segments extract_segments_from_voxels(const PointCloud& voxels, const Eigen::Vector3f& sensor_position,
                                      const SegmentationConfig& config, const std::vector<uint32_t>* voxel_labels,
                                      ModuleTimings* timings, const Deadline& deadline) {
  ModuleTimings local;
  return segments_of_voxels(voxels, sensor_position, config, voxel_labels, timings ? *timings : local, deadline, true);
}

Localizer::Localizer(const LocalizerConfig& config, Segments targets,
                     std::shared_ptr<const RandomForestMatcher> classifier, std::shared_ptr<const TargetPoints> points,
                     std::shared_ptr<const MapSurfaces> surfaces, PlacesFuture places)
    : config_(config),
      targets_(std::move(targets)),
      classifier_(std::move(classifier)),
      points_(std::move(points)),
      surfaces_(std::move(surfaces)),
      places_(std::move(places)) {
  config_.validate();
  centroids_ = CentroidIndex(targets_, config_.support_radius_m);
  if (config_.matcher.type == MatcherType::kRandomForest && !(classifier_ && classifier_->trained()))
    throw std::invalid_argument("the random forest matcher needs a trained classifier");
  for (const Segment& s : targets_) {
    if (!s.has_eigen) throw std::invalid_argument("map segment " + std::to_string(s.id) + " has no eigen features");
    if (config_.matcher.use_shapes && !s.has_esf)
      throw std::invalid_argument("map segment " + std::to_string(s.id) + " has no ESF descriptor");
  }
  index_.build(targets_);
}

Segments Localizer::segment_query(const PointCloud& cloud, const Eigen::Vector3f& sensor_position, CloudKind kind,
                                   ModuleTimings& timings, const Deadline& deadline) const {
  Stopwatch clock;
  Segments query = kind == CloudKind::kVoxelized
                       ? extract_segments_from_voxels(cloud, sensor_position, config_.segmentation, nullptr, &timings, deadline)
                       : extract_segments(cloud, sensor_position, config_.segmentation, nullptr, &timings, deadline);
  timings.total_ms = clock.lap();
  return query;
}

LocalizationResult Localizer::localize(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                                       CloudKind kind, const PosePrior* prior, const Deadline& deadline) const {
  check_prior(prior);
  if (deadline.passed()) return stopped({}, "before segmentation");  // it waited past it
  ModuleTimings timings;
  Segments query = segment_query(cloud, sensor_position, kind, timings, deadline);
  if (deadline.passed()) {  // the segments may be incomplete: never match them
    LocalizationResult r;
    r.timings = timings;
    return stopped(std::move(r), "during segmentation");
  }
  return localize_segments(std::move(query), sensor_position, prior, timings, deadline);
}

LocalizationResult Localizer::localize_tracking_first(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                                                      CloudKind kind, const PointCloud& newest, const PosePrior& prior,
                                                      const Deadline& deadline) const {
  check_prior(&prior);
  if (deadline.passed()) return stopped({}, "before segmentation");
  ModuleTimings timings;
  // Undescribed: tracking describes the few segments it checks, the fallback the rest.
  Stopwatch clock;
  Segments query = kind == CloudKind::kVoxelized
                       ? segments_of_voxels(cloud, sensor_position, config_.segmentation, nullptr, timings, deadline, false)
                       : segments_of_cloud(cloud, sensor_position, config_.segmentation, nullptr, timings, deadline, false);
  timings.total_ms = clock.lap();
  if (deadline.passed()) {
    LocalizationResult r;
    r.timings = timings;
    return stopped(std::move(r), "during segmentation");
  }
  LocalizationResult tracked = track(std::move(query), newest, sensor_position, prior);
  if (tracked.localized()) {
    const double tracking_ms = tracked.timings.refine_ms;
    tracked.timings = timings;
    tracked.timings.refine_ms = tracking_ms;
    tracked.timings.total_ms += tracking_ms;
    return tracked;
  }
  // A refused result keeps its query: the same segments go on, not segmented again.
  clock.lap();  // tracking's own time is in tracked.timings
  detail::describe_pending(tracked.query, nullptr, config_.segmentation.descriptors, deadline);
  const double describe_ms = clock.lap();
  timings.describe_ms += describe_ms;
  timings.total_ms += describe_ms;
  if (deadline.passed()) {
    LocalizationResult r;
    r.timings = timings;
    return stopped(std::move(r), "during description");
  }
  LocalizationResult r = localize_segments(std::move(tracked.query), sensor_position, &prior, timings, deadline);
  if (!deadline.passed()) refine_to_newest_scans(newest, sensor_position, r);
  keep_tracking_reason(tracked.reason, r);
  return r;
}

LocalizationResult Localizer::localize_segments(Segments query, const Eigen::Vector3f& sensor_position,
                                                const PosePrior* prior, const ModuleTimings& timings,
                                                const Deadline& deadline) const {
  check_prior(prior);
  LocalizationResult r;
  r.timings = timings;
  Stopwatch total, clock;
  const double before_ms = timings.total_ms;  // the caller's segmentation, if any
  auto finish = [&](LocalizationResult res) {
    res.timings.total_ms = before_ms + total.lap();
    return res;
  };
  const int min_inliers = config_.verification.min_inliers;
  r.query = std::move(query);
  r.query_segments = r.query.size();
  if (deadline.passed()) return finish(stopped(std::move(r), "before retrieval"));
  if (targets_.empty()) return finish(refuse(std::move(r), Refusal::kEmptyMap, "the map has no segments"));
  if (prior && config_.registration.enabled) {  // its time counts as refinement
    detail::register_near_prior(targets_, points_.get(), centroids_, classifier_.get(), config_, *prior, sensor_position, r);
    r.timings.refine_ms = clock.lap();
    if (r.localized()) return finish(std::move(r));
    r.refine_fitness = r.refine_rmse_m = 0.0f;
    r.support = 0;
    r.inliers.clear();
    if (deadline.passed()) return finish(stopped(std::move(r), "during registration"));
  }
  if (r.query.size() < static_cast<size_t>(min_inliers))
    return finish(refuse(std::move(r), Refusal::kTooFewSegments, "only " + std::to_string(r.query.size()) +
                                           " segments in the query cloud (at least " +
                                           std::to_string(min_inliers) + " needed)"));
  // Paper III-D: k-NN candidates in feature space (with a prior, among the map segments it
  // allows), then the classifier.
  const Matches candidates =
      prior ? retrieve_candidates_among(r.query, targets_, index_.scaling(),
                                        targets_near_prior(r.query, targets_, sensor_position, *prior), config_.retrieval)
            : retrieve_candidates(r.query, index_, config_.retrieval);
  r.candidates = candidates.size();
  r.timings.retrieve_ms = clock.lap();
  if (deadline.passed()) return finish(stopped(std::move(r), "during retrieval"));
  const Matches matches = filter_matches(r.query, targets_, candidates, config_.matcher, classifier_.get());
  r.matches = matches.size();
  r.timings.classify_ms = clock.lap();
  if (deadline.passed()) return finish(stopped(std::move(r), "during classification"));
  // Paper III-E: geometric verification on the segment centroids.
  VerificationResult v = verify_matches(r.query, targets_, matches, config_.verification, deadline);
  r.timings.verify_ms = clock.lap();
  if (deadline.passed()) return finish(stopped(std::move(r), "during verification"));
  if (!v.found)
    return finish(refuse(std::move(r), Refusal::kNoConsistentMatches, "no geometrically consistent set of " + std::to_string(min_inliers) +
                                           " matches among " + std::to_string(matches.size())));
  const size_t verified = v.hypotheses.size();
  const std::vector<PoseHypothesis> hypotheses = within_prior(std::move(v.hypotheses), sensor_position, prior);
  if (hypotheses.empty())
    return finish(refuse(std::move(r), Refusal::kOutsidePrior, "none of the " + std::to_string(verified) + " verified poses is within " +
                                           std::to_string(prior->radius_m) + " m of the prior"));
  // Beyond the paper: the hypothesis that explains most of the query wins, if unambiguous.
  const Ranked ranked = rank_by_support(hypotheses, r.query, centroids_, config_.support_radius_m);
  const PoseHypothesis& best = hypotheses[ranked.best];
  r.hypotheses = hypotheses.size();
  r.support = ranked.support.count();
  r.runner_up_support = ranked.runner_up;
  r.inliers = best.inliers;
  r.T_map_query = best.T_target_query;
  r.timings.verify_ms += clock.lap();
  const Floors floors = floors_of(config_, prior != nullptr);
  const int min_support = floors.min_support;
  if (r.support < static_cast<size_t>(min_support))
    return finish(refuse(std::move(r), Refusal::kLowSupport, "only " + std::to_string(r.support) + " query segments agree with the best pose (at least " +
                                           std::to_string(min_support) + " needed)"));
  if (static_cast<float>(r.runner_up_support) >= config_.max_ambiguity * static_cast<float>(r.support))
    return finish(refuse(std::move(r), Refusal::kAmbiguous, "ambiguous: two distinct poses are supported by " + std::to_string(r.support) +
                                           " and " + std::to_string(r.runner_up_support) + " query segments"));
  // With a prior, retrieval looked only where the prior puts each segment: a look-alike just
  // beyond it was never a hypothesis. A street of poles 6 m apart under a prior 6 m off and 3 m
  // wide was answered one pole off; the objects fit the truth as well (detail::look_alike_beside).
  if (prior) {
    std::string beside = detail::look_alike_beside(r.T_map_query, spread_axis(r.query, r.T_map_query), centroids_, config_,
                                                   detail::ambiguity_range_m(config_, *prior), r);
    if (!beside.empty()) return finish(refuse(std::move(r), Refusal::kAmbiguous, "ambiguous within the prior: " + beside));
  }
  r.refine_fitness = 1.0f;
  if (deadline.passed()) return finish(stopped(std::move(r), "during ranking"));
  if (config_.refine_pose) {
    const size_t stride = segment_point_stride(r.query, static_cast<size_t>(config_.refine.max_segment_points));
    const PointCloud query_points = gather(r.query, ranked.support.pairs, true, stride);
    const PointCloud target_points = gather(targets_, ranked.support.pairs, false, 1, points_.get());
    const RefineResult refined = refine_alignment(query_points, target_points, r.T_map_query, config_.refine,
                                                  r.T_map_query * sensor_position.cast<double>());
    r.timings.refine_ms += clock.lap();
    if (deadline.passed()) return finish(stopped(std::move(r), "during refinement"));
    r.refine_fitness = refined.fitness;
    r.refine_rmse_m = refined.rmse_m;
    if (refined.fitness < floors.min_fitness)
      return finish(refuse(std::move(r), Refusal::kSurfacesDisagree, "matched segments' surfaces disagree (fitness " +
                                             std::to_string(refined.fitness) + ")"));
    const float max_rmse_m = config_.max_refine_rmse_voxels * config_.segmentation.voxel.leaf_m;
    if (max_rmse_m > 0.0f && refined.rmse_m > max_rmse_m)
      return finish(refuse(std::move(r), Refusal::kSurfacesDisagree, "matched segments' surfaces are " +
                                             std::to_string(refined.rmse_m) + " m apart (RMS, at most " +
                                             std::to_string(max_rmse_m) + ")"));
    r.T_map_query = refined.T_target_query;
    r.covariance = pose_covariance(refined, config_.covariance);
    if (config_.refine.recent_window_m > 0.0f)
      detail::refine_recent_window(detail::window_points(r.query, targets_, points_.get(), sensor_position.cast<double>(), r.T_map_query,
                                         stride, config_.refine.recent_window_m),
                           sensor_position, floors.min_fitness, config_.refine, config_.covariance, r);
    r.timings.refine_ms += clock.lap();
  }
  r.confidence = confidence_of(r.support, min_support, r.refine_fitness);
  const float min_confidence = floors.min_confidence;
  if (r.confidence < min_confidence) {
    char why[96];
    std::snprintf(why, sizeof(why), "confidence %.2f below min_confidence %.2f", r.confidence, min_confidence);
    return finish(refuse(std::move(r), Refusal::kLowConfidence, why));
  }
  r.status = LocalizationStatus::kLocalized;
  return finish(std::move(r));
}

LocalizationResult Localizer::track(Segments query, const PointCloud& newest, const Eigen::Vector3f& sensor_position,
                                    const PosePrior& prior) const {
  check_prior(&prior);
  Stopwatch clock;
  LocalizationResult r;
  r.query = std::move(query);
  r.query_segments = r.query.size();
  detail::track_on_surfaces(newest, targets_, centroids_, classifier_.get(), surfaces_.get(), config_, prior, sensor_position, r);
  r.timings.refine_ms = r.timings.total_ms = clock.lap();
  return r;
}

void Localizer::refine_to_newest_scans(const PointCloud& newest, const Eigen::Vector3f& sensor_position,
                                       LocalizationResult& r) const {
  if (!config_.newest.enabled || !r.localized() || newest.empty()) return;
  Stopwatch clock;
  detail::refine_to_newest(newest, targets_, points_.get(), surfaces_.get(), config_, sensor_position, r);
  r.timings.refine_ms += clock.lap();
}

}  // namespace segmatch
