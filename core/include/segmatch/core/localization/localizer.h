// Localization against a prior segment map: the SegMatch pipeline of the paper (section III)
// in one place. A query local cloud is voxelized, its ground removed, segmented, described;
// its segments are matched to the map's by k-NN in feature space and a classifier, and the
// matches are verified geometrically, giving the 6DOF pose of the query in the map.
#pragma once

#include "segmatch/core/description/descriptors.h"
#include "segmatch/core/localization/correlative_search.h"
#include "segmatch/core/localization/place_recognition.h"
#include "segmatch/core/localization/registration.h"
#include "segmatch/core/matching/matcher.h"
#include "segmatch/core/matching/retrieval.h"
#include "segmatch/core/preprocess/preprocess.h"
#include "segmatch/core/segmentation/segment.h"
#include "segmatch/core/segmentation/segmenter.h"
#include "segmatch/core/verification/support.h"
#include "segmatch/core/verification/verification.h"

#include <algorithm>
#include <memory>
#include <string>

namespace segmatch {

// Cloud -> described segments (paper III-B and III-C).
struct SegmentationConfig {
  VoxelGridConfig voxel;
  GroundConfig ground;
  SegmenterConfig segmenter;
  DescriptorConfig descriptors;
  void validate() const;
};

struct LocalizerConfig {
  SegmentationConfig segmentation;
  RetrievalConfig retrieval;
  MatcherConfig matcher;
  VerificationConfig verification;
  RefineConfig refine;
  // Beyond the paper: a query with a prior is first registered to the map around it
  // (registration.h); segment matching answers when that does not.
  RegistrationConfig registration;
  CovarianceConfig covariance;     // of every localized answer
  NewestScansConfig newest;        // the sensor's pose now, when the query has its newest scans
  CorrelativeSearchConfig search;  // registration over priors too wide for ICP alone
  SurfaceTrackingConfig track;     // the newest scans onto the surface layer (Localizer::track)
  PlaceRecognitionConfig places;   // cold start: which place a scan shows (Localizer::recognize_place)
  // Beyond the paper: each verified hypothesis is ranked by its support (support.h), the
  // number of query segments that land within support_radius_m of a map segment under it.
  // The best must have at least min_support, and no other distinct hypothesis may reach
  // max_ambiguity times its support (a street of repeated poles or trees, seen too briefly
  // to tell which stretch it is, is refused rather than guessed).
  float support_radius_m = 1.0f;
  int min_support = 10;
  float max_ambiguity = 0.8f;
  bool refine_pose = true;  // beyond the paper: ICP on the supporting segments' points
  // Refined poses whose point fitness falls below this are reported as not localized: the
  // centroids agreed but the surfaces do not.
  float min_refine_fitness = 0.5f;
  // ... and so are refined poses whose query points lie farther than this many voxel edges
  // (segmentation.voxel.leaf_m) from the map's surfaces, RMS over the points with a neighbour.
  // Two voxelisations of one surface are a fraction of a voxel apart; a pose slid along a
  // street's repeated structure keeps most points within the 0.5 m correspondence distance
  // (fitness) but not that close. On simulated HDL-64E clouds (0.1 m voxels: the demo city and
  // the test cities) true poses gave at most 0.128 m, wrong or poor ones 0.166-0.215 m. 0: off.
  float max_refine_rmse_voxels = 1.5f;
  // Localized results whose confidence (LocalizationResult::confidence) falls below this are
  // reported as not localized. 0 (the core's default) keeps every pose that passed the checks
  // above; the kitti-hdl64 preset sets 0.8 (see io/pipeline_config.cpp for why).
  float min_confidence = 0.0f;
  // With a PosePrior the candidates and poses are already confined to where the vehicle is
  // known to be, so look-alikes elsewhere cannot pass; these replace min_support,
  // min_refine_fitness and min_confidence then (negative: the same as without a prior).
  int min_support_with_prior = -1;
  float min_refine_fitness_with_prior = -1.0f;
  float min_confidence_with_prior = -1.0f;
  void validate() const;
};

// The widest prior Localizer::track takes: registration's, or the correlative search's when it
// is on (the peaks are tracked from, surface_tracking.cpp). Clients ask to track first up to it.
inline double max_tracked_radius_m(const LocalizerConfig& c) {
  return c.search.enabled ? std::max<double>(c.search.max_radius_m, c.registration.max_prior_radius_m)
                          : c.registration.max_prior_radius_m;
}

enum class LocalizationStatus { kLocalized, kNotLocalized };
const char* to_string(LocalizationStatus status);

// What answered: segment matching (the paper's pipeline, and the global path), the
// registration to the map around a prior (registration.h), or the newest scans registered onto
// the surface layer around a prior (Localizer::track), or around a place the query's scan
// resembles (Localizer::recognize_place: a cold start without a prior).
enum class LocalizationMethod { kSegments, kRegistration, kSurfaces, kPlaces };
const char* to_string(LocalizationMethod method);

// Why a query was not localized, stage by stage (LocalizationResult::reason says it in words).
enum class Refusal {
  kNone,                 // localized
  kEmptyMap,             // the map has no segments
  kTooFewSegments,       // fewer query segments than verification.min_inliers
  kNoConsistentMatches,  // geometric verification found no consistent set
  kOutsidePrior,         // poses were verified, none within the prior's radius
  kLowSupport,           // too few query segments agree with the best pose
  kAmbiguous,            // another distinct pose is supported almost as well
  kSurfacesDisagree,     // refinement fitness below min_refine_fitness
  kLowConfidence,        // confidence below min_confidence
  kDeadlinePassed,       // the query's deadline passed before it was answered (Deadline)
  kOffMap,               // the vehicle's newest scans do not lie on the map's surfaces at the answer
  kNewestScansDisagree,  // ... they do, but settle farther from it than NewestScansConfig allows
  kTrackingLost,         // Localizer::track: the newest scans did not register around the prior
};
const char* to_string(Refusal refusal);

// Wall-clock time of each module for one query (milliseconds).
struct ModuleTimings {
  double voxel_ms = 0, ground_ms = 0, segment_ms = 0, describe_ms = 0, retrieve_ms = 0, classify_ms = 0, verify_ms = 0,
         refine_ms = 0, total_ms = 0;
};

struct LocalizationResult {
  LocalizationStatus status = LocalizationStatus::kNotLocalized;
  Refusal refusal = Refusal::kNone;         // why not localized, typed
  std::string reason;                       // the same in words (empty if localized)
  Pose3d T_map_query = Pose3d::Identity();  // maps query-frame points into the map frame
  Matches inliers;                          // query index -> map segment index
  float confidence = 0.0f;                  // 0..1
  float refine_fitness = 0.0f;              // fraction of query points on map surfaces
  float refine_rmse_m = 0.0f;
  // The recent window's refinement (RefineConfig::recent_window_m): how far the whole cloud's
  // pose and the window's differ at the sensor, and the window's query points (0: not run,
  // or too few points and the whole cloud's pose stands).
  float window_warp_m = 0.0f, window_warp_deg = 0.0f;
  size_t window_points = 0;
  LocalizationMethod method = LocalizationMethod::kSegments;
  // The pose's 6x6 covariance (pose_covariance in registration.h): rotation in radians about
  // the map frame's axes through the sensor, then the sensor's position in metres, map frame.
  // Zero when there is none (not localized, or point-to-point refinement).
  Matrix6d covariance = Matrix6d::Zero();
  // With a prior and registration on: why registration did not answer (kNone: it did, or it
  // was not tried), typed and in words.
  RegistrationRefusal registration_refusal = RegistrationRefusal::kNone;
  std::string registration_reason;
  // With the vehicle's newest scans (refine_to_newest_scans): whether they moved the answer
  // (kNone) or why not, typed and in words; kNone and empty when none were given.
  RegistrationRefusal newest_refusal = RegistrationRefusal::kNone;
  std::string newest_reason;
  size_t query_segments = 0, candidates = 0, matches = 0;
  size_t hypotheses = 0;                      // distinct verified poses considered
  size_t support = 0, runner_up_support = 0;  // of the chosen and the next-best pose
  Segments query;                             // the query's described segments (query frame)
  ModuleTimings timings;
  bool localized() const { return status == LocalizationStatus::kLocalized; }
};

// A refusal that came after tracking on the surface layer did not answer says why tracking did
// not either: "<the refusal's reason> (tracking on the surface layer: ...)". Answers are untouched.
inline void keep_tracking_reason(const std::string& tracking_reason, LocalizationResult& r) {
  if (!r.localized() && !tracking_reason.empty()) r.reason += " (" + tracking_reason + ")";
}

// Voxel grid, ground removal, segmentation and description of one cloud. sensor_position
// is in the cloud's frame (the height threshold needs it). Labels, if given, mark each
// segment with its majority ground-truth label.
// Once `deadline` has passed, the stages still to run are skipped (the caller checks it).
// With SegmenterType::kRangeImage and a raw scan that shows rings, the ground-free raw points
// are segmented in the scan's range image before the voxel grid (segmenter.h).
Segments extract_segments(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                          const SegmentationConfig& config, const std::vector<uint32_t>* labels = nullptr,
                          ModuleTimings* timings = nullptr, const Deadline& deadline = {});

// The same without the voxel grid: ground removal, segmentation and description of an
// already voxelized cloud (voxel_filter's output, e.g. VoxelAccumulator::crop) with its
// per-voxel labels. extract_segments(cloud) == extract_segments_from_voxels(voxel_filter(cloud)), except
// for kRangeImage on a raw scan (above).
Segments extract_segments_from_voxels(const PointCloud& voxels, const Eigen::Vector3f& sensor_position,
                                      const SegmentationConfig& config,
                                      const std::vector<uint32_t>* voxel_labels = nullptr,
                                      ModuleTimings* timings = nullptr, const Deadline& deadline = {});

// The stride s with which every segment keeps every s-th of its points so that at most
// max_points remain in all (1 when they already fit or max_points is 0): RefineConfig's
// max_segment_points cut, the same on the server and on a vehicle (docs/protocol.md 5.5).
size_t segment_point_stride(const Segments& segments, size_t max_points);
// Applies that cut: segment i keeps points 0, s, 2s, ... of its own.
void thin_segment_points(Segments& segments, size_t max_points);

// The points of `cloud` within radius_m horizontally of `center`: the local cylinder of the
// paper (III-A), cut from whatever the vehicle sent.
PointCloud crop_cylinder(const PointCloud& cloud, const Eigen::Vector3d& center, double radius_m);

// The points of `cloud` seen from `sensor` at an elevation (degrees above the horizontal plane)
// within [min_deg, max_deg]: what a sensor with that vertical field of view could see from there.
PointCloud crop_elevation(const PointCloud& cloud, const Eigen::Vector3f& sensor, double min_deg, double max_deg);

// Version of the segmentation and description code: part of the digest that names the
// parameters a vehicle's segments were computed with (docs/protocol.md 5.5). Bump it whenever
// a change makes the same cloud and parameters give other segments or descriptors.
constexpr uint32_t kSegmentCodeVersion = 1;

// What a query cloud holds: raw points, or one point per occupied voxel of the map's grid.
enum class CloudKind { kRaw, kVoxelized };

// Where the query is believed to be (e.g. GNSS, the last fix plus odometry, or odometry itself
// for loop closure): verified hypotheses that put the sensor farther than radius_m from where
// T_map_query puts it are discarded before ranking, so the prior also settles a choice between
// distant look-alike places that the support alone would refuse as ambiguous.
// The prior narrows retrieval itself (so that the few matches of the right place are neither
// crowded out of the k nearest by look-alikes elsewhere in a large map nor outnumbered by a
// larger cluster elsewhere): a query segment at distance d from the sensor retrieves its k
// nearest in feature space only among the map segments within radius_m + d * max_rotation_deg
// (in radians) of where the prior puts it.
struct PosePrior {
  Pose3d T_map_query = Pose3d::Identity();
  double radius_m = 10.0;          // search radius around the prior's sensor position (finite, > 0)
  double max_rotation_deg = 10.0;  // heading error the prior may have (finite, >= 0)
};

// The map segments' points, for a localizer whose targets are held without them (a server
// keeping a city map's points on disk). Only refinement reads points: those of the few dozen
// matched segments of a query; retrieval, classification and verification need the rest.
class TargetPoints {
 public:
  virtual ~TargetPoints() = default;
  // Appends the points of targets[index] to `out`. Called from many queries at once; throws
  // (with a message naming the segment) when they cannot be read.
  virtual void append(size_t index, PointCloud* out) const = 0;
};

// The map's surface layer (beyond the paper): every surface the mapping run saw, ground and
// walls included, thinned to a voxel grid, in tiles (a server reads them from the map file on
// demand). Registration onto it holds the height, roll and pitch that segments alone (no ground)
// leave weak. Null when the map has none (maps written before it).
class MapSurfaces {
 public:
  virtual ~MapSurfaces() = default;
  // Exactly the layer's points (map frame) within radius_m of center horizontally, as
  // crop_cylinder keeps them ((x - cx)^2 + (y - cy)^2 <= r^2 in double): callers do not crop
  // again (the layer near a query is 1-2 MB, copied once). Called from many queries at once;
  // throws (naming the tile) when they cannot be read.
  virtual PointCloud near(const Eigen::Vector3d& center, double radius_m) const = 0;
};

class Localizer {
 public:
  // targets: the map's described segments (map frame). classifier: required for the random
  // forest matcher, ignored for L2. points: where refinement reads the targets' points; null
  // when the targets hold them (given, the targets' own points are not read).
  // surfaces: the map's surface layer, onto which the newest scans are registered (null: onto
  // the segments' points, ground removed from the scans).
  Localizer(const LocalizerConfig& config, Segments targets,
            std::shared_ptr<const RandomForestMatcher> classifier = nullptr,
            std::shared_ptr<const TargetPoints> points = nullptr, std::shared_ptr<const MapSurfaces> surfaces = nullptr,
            PlacesFuture places = {});

  // cloud: local cloud in the query (vehicle odometry) frame; sensor_position: the sensor in
  // that frame. Thread-safe: many queries may run at once.
  // With CloudKind::kVoxelized the cloud is already voxel_filter'ed with
  // config().segmentation.voxel (e.g. a vehicle's VoxelAccumulator): the voxel grid is skipped.
  // With a prior, only poses within prior->radius_m of it are considered (see PosePrior).
  // Past `deadline`, the query stops and is refused with Refusal::kDeadlinePassed.
  LocalizationResult localize(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                              CloudKind kind = CloudKind::kRaw, const PosePrior* prior = nullptr,
                              const Deadline& deadline = {}) const;

  // The same from the query's described segments (query frame), as extract_segments gives
  // them: everything after description (retrieval, classification, verification, ranking,
  // refinement). localize(cloud) is extract_segments then this, so a vehicle that segments
  // its own cloud with the map's SegmentationConfig gets the server's answer. `timings`
  // carries the caller's voxel..describe times into the result.
  LocalizationResult localize_segments(Segments query, const Eigen::Vector3f& sensor_position,
                                       const PosePrior* prior = nullptr, const ModuleTimings& timings = {},
                                       const Deadline& deadline = {}) const;

  // The sensor's pose now (NewestScansConfig): refines a localized r with the vehicle's newest
  // scans (query frame; raw, or thinned to config().newest.leaf_m), replacing its pose and
  // covariance, and setting its window fields to the difference, when they agree with it.
  // Leaves r as it is otherwise, when disabled, or when r is not localized. Thread-safe.
  void refine_to_newest_scans(const PointCloud& newest, const Eigen::Vector3f& sensor_position,
                              LocalizationResult& r) const;

  // localize() for a tracked vehicle that sends its newest scans (LOCALIZE bit 6, revision 11):
  // the cloud's segments go to track() first; when it does not answer, the same segments go on
  // to localize_segments() with the prior, and the answer is refined to the newest scans.
  LocalizationResult localize_tracking_first(const PointCloud& cloud, const Eigen::Vector3f& sensor_position,
                                             CloudKind kind, const PointCloud& newest, const PosePrior& prior,
                                             const Deadline& deadline = {}) const;

  // Tracking on the surface layer (SurfaceTrackingConfig): the newest scans (query frame)
  // registered onto the map's surface layer around `prior`, the pose checked against the
  // query's segments (centroids and features; their points are not read). Localized with
  // LocalizationMethod::kSurfaces, or refused with Refusal::kTrackingLost and the reason (no
  // layer, a prior too wide, a gate). Thread-safe.
  LocalizationResult track(Segments query, const PointCloud& newest, const Eigen::Vector3f& sensor_position,
                           const PosePrior& prior) const;

  // Cold start (place_recognition.h): a query without a prior that segment matching refused
  // (`refused`, whose query segments are kept for the checks) is described around the sensor
  // from `cloud` (query frame); the map's places most like it are priors for tracking `newest`
  // on the surface layer (track(), every gate). One place passing answers, with
  // LocalizationMethod::kPlaces; two at distinct places are an ambiguity. `refused` comes back
  // as it was, its reason extended, when no place answers or the map has no places.
  LocalizationResult recognize_place(LocalizationResult refused, const PointCloud& cloud, const PointCloud& newest,
                                     const Eigen::Vector3f& sensor_position) const;

  const Segments& targets() const { return targets_; }
  const LocalizerConfig& config() const { return config_; }
  const FeatureIndex& feature_index() const { return index_; }
  const RandomForestMatcher* classifier() const { return classifier_.get(); }
  const MapSurfaces* surfaces() const { return surfaces_.get(); }
  // The map's places (waits while they are being described); null without.
  const PlaceIndex* places() const { return places_.valid() ? places_.get().get() : nullptr; }

 private:
  // Voxel grid (unless kVoxelized), ground removal, segmentation and description of a query
  // cloud; fills timings' voxel..describe and total.
  Segments segment_query(const PointCloud& cloud, const Eigen::Vector3f& sensor_position, CloudKind kind,
                         ModuleTimings& timings, const Deadline& deadline) const;

  LocalizerConfig config_;
  Segments targets_;
  FeatureIndex index_;
  CentroidIndex centroids_;
  std::shared_ptr<const RandomForestMatcher> classifier_;
  std::shared_ptr<const TargetPoints> points_;
  std::shared_ptr<const MapSurfaces> surfaces_;
  PlacesFuture places_;
};

}  // namespace segmatch
