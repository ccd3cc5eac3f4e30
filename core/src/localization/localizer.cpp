#include "segmatch/core/localization/localizer.h"

#include "localization/localizer_stages.h"
#include "localization/segment_stages.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace segmatch {
namespace {

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
using detail::stopped;

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
  const double lo = std::tan(std::max(min_deg, -89.9) * M_PI / 180.0),
               hi = std::tan(std::min(max_deg, 89.9) * M_PI / 180.0);
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
    throw std::invalid_argument(
        "min_support_with_prior must be at least verification.min_inliers (or negative: unused)");
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
Segments segments_of_voxels(const PointCloud& voxels, const Eigen::Vector3f& sensor_position,
                            const SegmentationConfig& config, const std::vector<uint32_t>* voxel_labels,
                            ModuleTimings& t, const Deadline& deadline, bool describe) {
  Stopwatch clock;
  std::vector<uint32_t> foreground_labels;
  const PointCloud foreground =
      remove_ground(voxels, config.ground, sensor_position, voxel_labels, voxel_labels ? &foreground_labels : nullptr);
  t.ground_ms = clock.lap();
  if (deadline.passed()) return {};
  Segments segments = segment_cloud(foreground, config.segmenter, voxel_labels ? &foreground_labels : nullptr);
  t.segment_ms = clock.lap();
  if (deadline.passed()) return {};
  if (describe) describe_segments(segments, config.descriptors, deadline);
  t.describe_ms = clock.lap();
  return segments;
}

// kRangeImage on a raw scan (segmenter.h): the ground-free raw points are labelled in the scan's
// range image, which voxels would blur, then voxelized with their components as labels, so the
// segments hold voxels as every other segmenter's do. False (nothing done) when the scan shows
// no range image (no rings): the caller clusters it as kEuclidean, and counts fit_ms (the time
// spent finding that out) as segmentation.
bool segments_of_scan(const PointCloud& cloud, const Eigen::Vector3f& sensor_position, const SegmentationConfig& config,
                      const std::vector<uint32_t>* labels, ModuleTimings& t, const Deadline& deadline, bool describe,
                      Segments* out, double* fit_ms) {
  Stopwatch clock;
  const RangeImageGrid grid = fit_range_image(cloud, sensor_position, config.segmenter);
  double segment_ms = *fit_ms = clock.lap();
  if (!grid.valid()) return false;
  std::vector<uint32_t> foreground_labels;
  const PointCloud foreground =
      remove_ground(cloud, config.ground, sensor_position, labels, labels ? &foreground_labels : nullptr);
  t.ground_ms = clock.lap();
  if (deadline.passed()) return true;
  const std::vector<uint32_t> components = range_image_components(grid, foreground, config.segmenter);
  segment_ms += clock.lap();
  std::vector<uint32_t> voxel_components, voxel_labels;
  const PointCloud voxels = voxel_filter(foreground, config.voxel, &components, &voxel_components);
  if (labels) voxel_filter(foreground, config.voxel, &foreground_labels, &voxel_labels);  // same voxels, same order
  t.voxel_ms = clock.lap();
  if (deadline.passed()) return true;
  *out = segments_of_components(voxels, voxel_components, config.segmenter, labels ? &voxel_labels : nullptr);
  t.segment_ms = segment_ms + clock.lap();
  if (deadline.passed()) return true;
  if (describe) describe_segments(*out, config.descriptors, deadline);
  t.describe_ms = clock.lap();
  return true;
}

Segments segments_of_cloud(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                           const SegmentationConfig& config, const std::vector<uint32_t>* labels, ModuleTimings& t,
                           const Deadline& deadline, bool describe) {
  Segments scan_segments;
  double fit_ms = 0.0;
  if (config.segmenter.type == SegmenterType::kRangeImage &&
      segments_of_scan(cloud, sensor_position, config, labels, t, deadline, describe, &scan_segments, &fit_ms))
    return scan_segments;
  Stopwatch clock;
  std::vector<uint32_t> voxel_labels;
  const PointCloud voxels = voxel_filter(cloud, config.voxel, labels, labels ? &voxel_labels : nullptr);
  t.voxel_ms = clock.lap();
  if (deadline.passed()) return {};
  Segments segments =
      segments_of_voxels(voxels, sensor_position, config, labels ? &voxel_labels : nullptr, t, deadline, describe);
  t.segment_ms += fit_ms;
  return segments;
}

}  // namespace

Segments extract_segments(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                          const SegmentationConfig& config, const std::vector<uint32_t>* labels, ModuleTimings* timings,
                          const Deadline& deadline) {
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
  Segments query =
      kind == CloudKind::kVoxelized
          ? extract_segments_from_voxels(cloud, sensor_position, config_.segmentation, nullptr, &timings, deadline)
          : extract_segments(cloud, sensor_position, config_.segmentation, nullptr, &timings, deadline);
  timings.total_ms = clock.lap();
  return query;
}

LocalizationResult Localizer::localize(const PointCloud& cloud, const Eigen::Vector3f& sensor_position, CloudKind kind,
                                       const PosePrior* prior, const Deadline& deadline) const {
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
  Segments query =
      kind == CloudKind::kVoxelized
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

// The paper's pipeline after segmentation, one named stage a line (segment_stages.h).
LocalizationResult Localizer::localize_segments(Segments query, const Eigen::Vector3f& sensor_position,
                                                const PosePrior* prior, const ModuleTimings& timings,
                                                const Deadline& deadline) const {
  using namespace detail;
  check_prior(prior);
  const SegmentMap map{config_, targets_, index_, centroids_, classifier_.get(), points_.get()};
  const SegmentQuery q{sensor_position, prior};
  SegmentWork w;
  LocalizationResult r;
  r.timings = timings;
  r.query = std::move(query);
  r.query_segments = r.query.size();
  StageRunner run(r, deadline);
  if (deadline.passed()) return stopped(run.finish(), "before retrieval");
  if (targets_.empty()) return refuse(run.finish(), Refusal::kEmptyMap, "the map has no segments");
  using T = ModuleTimings;
  if (prior && config_.registration.enabled &&
      !run(&T::refine_ms, "during registration", [&] { return register_first(map, q, r); }))
    return run.finish();
  // Each stage runs when the one before went on.
  (void)(run(nullptr, nullptr, [&] { return enough_segments(map, r); }) &&
         run(&T::retrieve_ms, "during retrieval", [&] { return retrieve(map, q, r, w); }) &&
         run(&T::classify_ms, "during classification", [&] { return classify(map, r, w); }) &&
         run(&T::verify_ms, "during verification", [&] { return verify(map, deadline, r, w); }) &&
         run(&T::verify_ms, nullptr, [&] { return apply_prior(q, r, w); }) &&
         run(&T::verify_ms, "during ranking", [&] { return rank(map, q, r, w); }) &&
         run(&T::refine_ms, "during refinement", [&] { return refine(map, q, r, w); }) &&
         run(nullptr, nullptr, [&] { return confidence(map, q, r); }));
  return run.finish();
}

LocalizationResult Localizer::track(Segments query, const PointCloud& newest, const Eigen::Vector3f& sensor_position,
                                    const PosePrior& prior) const {
  check_prior(&prior);
  Stopwatch clock;
  LocalizationResult r;
  r.query = std::move(query);
  r.query_segments = r.query.size();
  detail::track_on_surfaces(newest, targets_, centroids_, classifier_.get(), surfaces_.get(), config_, prior,
                            sensor_position, r);
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
