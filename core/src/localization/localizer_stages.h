// The localizer's point stages (localizer.cpp): gathering segment points, the recent window's
// refinement and the registration around a prior. Private to the core.
#pragma once

#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/verification/support.h"

#include <vector>

namespace segmatch {
namespace detail {

constexpr double kWindowMarginM = 10.0;  // map segments (or surfaces) straddling a window's edge

// The map segments whose centroids lie within radius_m of center, horizontally.
// r, not localized, with its typed refusal and the reason in words (a refused pose has no
// covariance).
LocalizationResult refuse(LocalizationResult r, Refusal refusal, std::string why);

std::vector<int> targets_within_disc(const Segments& targets, const Eigen::Vector3d& center, double radius_m);

// Points of the segments on one side of the matches, for the refinement: every stride-th point
// of each segment (segment_point_stride).
// With `source`, a target's points come from there (the same points, in the same order).
PointCloud gather(const Segments& segments, const Matches& inliers, bool query_side, size_t stride = 1,
                  const TargetPoints* source = nullptr);

// The recent window's points (RefineConfig::recent_window_m), see localizer_stages.cpp.
struct WindowPoints {
  PointCloud query, targets;
};
WindowPoints window_points(const Segments& query, const Segments& targets, const TargetPoints* source,
                           const Eigen::Vector3d& sensor, const Pose3d& T_map_query, size_t stride, float window_m);

// The sensor's pose now: the window refined alone from the whole cloud's pose (sets the
// result's pose, window fields and covariance when the window fits).
void refine_recent_window(const WindowPoints& points, const Eigen::Vector3f& sensor, float min_fitness,
                          const RefineConfig& config, const CovarianceConfig& covariance, LocalizationResult& r);

// Query segments that carry no descriptor yet (the tracking path segments a cloud without
// describing it): described here, the ones listed in `pairs` (those a pose puts on map
// segments) or, with pairs null, every one. A segment's descriptor depends on its own points
// (describe_segments), so describing later gives the same descriptors and answers.
void describe_pending(Segments& query, const Matches* pairs, const DescriptorConfig& config,
                      const Deadline& deadline = {});

// The segment check of a registered pose: enough query segments land on map segments
// (RegistrationConfig::min_support), and at least min_matched_segments of those pairs pass the
// matcher (the registration's floor, or the surface layer's: SurfaceTrackingConfig). Fills r's
// support and inliers; false, with r's registration refusal, when too few.
bool well_supported(const Segments& targets, const CentroidIndex& centroids, const RandomForestMatcher* classifier,
                    const LocalizerConfig& config, const Pose3d& T_map_query, int min_matched_segments,
                    LocalizationResult& r);

// A pose registered from a correlative search peak still answers the wide prior it came from:
// inside its disc and heading tolerance, with the search's fitness floor
// (CorrelativeSearchConfig::min_fitness). False with the refusal and its reason otherwise.
bool within_wide_prior(const RegistrationResult& reg, const PosePrior& prior, const Eigen::Vector3d& s,
                       const CorrelativeSearchConfig& search, RegistrationRefusal& refusal, std::string& reason);

// Whether the query's objects fit a pose beside the chosen one as well: its support
// (support.h) under the pose shifted horizontally along `along` (the street) and across it,
// 1.5 m to range_m. Empty when no shift reaches SurfaceTrackingConfig::max_shifted_support times
// r.support; otherwise the refusal's reason. Every path that answers within a prior asks it: a
// prior picks one of a street's look-alikes but cannot tell whether it is the right one.
std::string look_alike_beside(const Pose3d& T_map_query, const Eigen::Vector3d& along, const CentroidIndex& centroids,
                              const LocalizerConfig& config, double range_m, const LocalizationResult& r);
// look_alike_beside for a registered pose, along its weakest axis: walls and ground hold a
// street's cross-section, not where along it the vehicle is (a scan registered a few metres
// along a street of look-alike facades fits them: fitness 0.89 on the simulated demo city, a
// prior 6 m off), while the objects fit at the truth, where their support is far higher. False,
// with r's registration refusal (kAmbiguous) and reason, when a look-alike is beside it.
bool unambiguous_along_street(const RegistrationResult& reg, const CentroidIndex& centroids,
                              const LocalizerConfig& config, double range_m, LocalizationResult& r);
// How far from an answer look-alikes are sought: SurfaceTrackingConfig::ambiguity_range_m, or
// the prior's diameter when wider (every pose the prior allows, and the truth just beyond it).
double ambiguity_range_m(const LocalizerConfig& config, const PosePrior& prior);
// The verified hypotheses (prior_hypotheses.cpp). The one with the most support, and the
// runner-up's support:
struct Ranked {
  size_t best = 0;
  Support support;
  size_t runner_up = 0;
};
Ranked rank_by_support(const std::vector<PoseHypothesis>& hypotheses, const Segments& query, const CentroidIndex& map,
                       float radius_m);
// Those that put the sensor within the prior's radius and turn it by at most its
// max_rotation_deg (all of them without a prior).
std::vector<PoseHypothesis> within_prior(std::vector<PoseHypothesis> hypotheses, const Eigen::Vector3f& sensor,
                                         const PosePrior* prior);
// The direction the query's segments spread along under a pose, horizontally (the street's, for
// a local cloud driven along one): the principal axis of their centroids.
Eigen::Vector3d spread_axis(const Segments& query, const Pose3d& T_map_query);
// Per query segment, the map segments lying where the prior, within its tolerances, puts it.
std::vector<std::vector<int>> targets_near_prior(const Segments& query, const Segments& targets,
                                                 const Eigen::Vector3f& sensor, const PosePrior& prior);

// Whether reg's sensor lies at least min_separation_m from every pose already passed.
bool distinct_from(const std::vector<RegistrationResult>& passed, const RegistrationResult& reg,
                   const Eigen::Vector3d& s, double min_separation_m);

// A registration's answer as r's: localized by `method`, its pose, covariance and fitness.
void localized_by(const RegistrationResult& reg, LocalizationResult& r,
                  LocalizationMethod method = LocalizationMethod::kRegistration);

// Tracking by registration (registration.h): localizes r, or says in r why registration did not.
void register_near_prior(const Segments& targets, const TargetPoints* source, const CentroidIndex& centroids,
                         const RandomForestMatcher* classifier, const LocalizerConfig& config, const PosePrior& prior,
                         const Eigen::Vector3f& sensor, LocalizationResult& r);

// The sensor's pose now from the vehicle's newest scans (NewestScansConfig): sets r's pose,
// covariance and window fields when they agree with it.
// With the map's surface layer the scans keep their ground and register onto it; without, onto
// the segments' points, ground removed.
// Tracking on the surface layer (Localizer::track, SurfaceTrackingConfig; surface_tracking.cpp):
// localized by the newest scans' registration around the prior, or refused with
// Refusal::kTrackingLost.
void track_on_surfaces(const PointCloud& newest, const Segments& targets, const CentroidIndex& centroids,
                       const RandomForestMatcher* classifier, const MapSurfaces* surfaces,
                       const LocalizerConfig& config, const PosePrior& prior, const Eigen::Vector3f& sensor,
                       LocalizationResult& r);

void refine_to_newest(const PointCloud& newest, const Segments& targets, const TargetPoints* source,
                      const MapSurfaces* surfaces, const LocalizerConfig& config, const Eigen::Vector3f& sensor,
                      LocalizationResult& r);

}  // namespace detail
}  // namespace segmatch
