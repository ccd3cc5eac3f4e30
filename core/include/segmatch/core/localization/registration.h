// Registration to the map around a prior (beyond the paper). The paper localizes every query
// by segment matching; localizers that fleets run use place recognition only to find a first
// pose, and between fixes register the local cloud to the map around the predicted pose. Here a
// query with a prior is first registered, by the point-to-plane ICP of refine.cpp, to the map
// segments' points near the prior; segment matching is the fallback and the global path.
//
// A registration answers only when it is well posed and well supported: its query points lie
// on the map's surfaces (fitness, RMS), it stayed within the prior, and the surfaces it used
// constrain every direction (a straight corridor of walls leaves the motion along it free; the
// Gauss-Newton information along its weakest axis shows that). Every answer carries a 6x6
// covariance from that information.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/core/verification/verification.h"

#include <Eigen/Core>

#include <string>

namespace segmatch {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

struct RegistrationConfig {
  bool enabled = true;
  // Query points within this horizontal distance of the sensor are registered: the odometry
  // that built the local cloud drifts along it, near the sensor least.
  float window_m = 40.0f;
  // A first ICP with this correspondence distance brings a prior that is off by a metre or two
  // within reach of the fine one (RefineConfig::max_correspondence_m).
  float coarse_correspondence_m = 1.5f;
  // ... onto the map's points thinned to this voxel grid (0: at full density). Only the fine
  // stage decides the answer and its gates.
  float coarse_leaf_m = 0.5f;
  // Off: the fine stage starts at the prior itself (SurfaceTrackingConfig::fine_first_m).
  bool coarse_stage = true;
  // Priors wider than this are not a starting point for ICP (its basin is a metre or two): such
  // queries go to segment matching directly. On riverside02 with GNSS-like priors (sigma 10 m,
  // radius 30 m) registration found wrong minima along the street, 1-15 m off with fitness up
  // to 0.82, and on hku-mb (sigma 3 m, radius 9 m) one 1.1 m off (docs/how-defaults-were-chosen.md); a tracker's prior
  // (api::Tracker, at least 3 m) is a metre or less off after a fix, and wider than 10 m only
  // after some 160 m without one.
  float max_prior_radius_m = 10.0f;
  int min_query_points = 300;
  // The fine ICP must have settled: converged, or its last iteration moved the pose by at most
  // this (m + rad). From priors 4 m off (outside the basin) it was still being dragged when it
  // stopped, and answered 1.5 m off (riverside02, --wrong-prior-m 4).
  float max_last_step_m = 0.01f;
  // At least this many query segments land on a map segment under the registered pose (their
  // centroids within LocalizerConfig::support_radius_m, support.h), as the segment path asks of
  // its poses: the surfaces of a street's facades can agree at a wrong place, its objects not.
  int min_support = 10;
  // ... and at least this many of those pairs pass the matcher (the classifier, as in segment
  // matching): segments that land on a map segment by coincidence are other objects. Measured
  // (docs/how-defaults-were-chosen.md): true registrations had 2 or more (riverside02 2, demo 6, hku-mb 32 at the
  // least), registrations from priors 6 m off 0.
  int min_matched_segments = 3;
  // At least this fraction of the query points within the fine correspondence distance of the
  // map's surfaces.
  float min_fitness = 0.55f;
  // Degeneracy: the translation information per correspondence along the weakest axis (the
  // smallest eigenvalue of the translation block, rotation marginalised, divided by the
  // number of correspondences: the share of the surface normals that point along it, 0..1/3).
  float min_axis_share = 0.02f;
  void validate() const;  // throws std::invalid_argument naming the field
};

// The sensor's pose now, from the vehicle's newest scans (beyond the paper; docs/protocol.md
// 5.4, flag bit 5). A local cloud is placed by the vehicle's odometry, which drifts across it,
// so the pose that fits the whole cloud is off at the sensor by part of that drift: on the demo
// city's LiDAR-inertial-like odometry the heading error of tracked answers was 0.10 deg median
// and 0.41 deg at worst, against 0.006 deg with reference-built clouds. The scans of the last
// few metres carry almost none of it. They are registered alone, from the answer: thinned to
// leaf_m, ground removed, onto the map segments' points near the sensor; the answer moves only
// when they fit, settled, near it, and constrain every axis.
struct NewestScansConfig {
  bool enabled = true;
  float window_m = 40.0f;     // newest points within this horizontal distance of the sensor
  float leaf_m = 0.2f;        // voxel grid they are thinned to (one point per occupied voxel)
  int min_points = 300;       // after thinning and ground removal
  float min_fitness = 0.55f;  // as RegistrationConfig::min_fitness
  float max_shift_m = 1.0f;   // farther from the answer at the sensor: the answer stands
  float max_turn_deg = 2.0f;  // ... or turned more than this
  // With a surface layer (every surface the mapping run saw), newest scans that do not lie on
  // it at the answer (fitness below min_fitness, or no layer near the sensor) mean the sensor
  // sees what the map never saw: an unmapped street. The answer is then a pose extrapolated
  // through the odometry's warp, unverified where the vehicle is: refused (Refusal::kOffMap).
  // Newest scans that lie on it but settle farther than max_shift_m (or turn past max_turn_deg)
  // from the answer put the sensor elsewhere: refused too (Refusal::kNewestScansDisagree).
  // Off: such answers stand. Without a layer the segments cover too little of the scene
  // for their fitness to say this, and the answer stands.
  bool refuse_off_map = true;
  void validate() const;  // throws std::invalid_argument naming the field
};

// Tracking on the surface layer (beyond the paper; docs/protocol.md 5.5, bit 5): a vehicle with
// a fix sends its newest scans and its segments' centroids and features, no segment points.
// The scans, thinned to leaf_m, are registered onto the layer around the prior (a tracker's:
// RegistrationConfig::max_prior_radius_m at most) with the registration's gates and
// min_fitness here, and the pose must be supported by the segments as every registration is
// (RegistrationConfig::min_support, min_matched_segments): walls and ground agree along a
// street anywhere, its objects only at the right place. Its ICP reads a few thousand points,
// not the segments' tens of thousands, and no segment points travel (docs/how-defaults-were-chosen.md).
struct SurfaceTrackingConfig {
  bool enabled = true;
  float leaf_m = 0.5f;     // the newest scans are thinned to this voxel grid
  float window_m = 40.0f;  // ... within this horizontal distance of the sensor
  int min_points = 200;    // after thinning
  // A tracking request carries at most this many newest points (every k-th after thinning) and
  // only the segments within window_m of the sensor: the ICP reads RefineConfig::max_query_points
  // (2000) of them anyway, and nearby segments are those the odometry placed best.
  int max_points = 2000;
  // Of the fine stage, as RegistrationConfig::min_fitness. The one false answer of the
  // wrong-prior stress without the check below had 0.89: fitness says the scans lie on surfaces,
  // not that they lie at the right place along them. 0.75 refused true answers on the bench's
  // tiny city, whose revisit sees a changed world (0.52-0.62; docs/how-defaults-were-chosen.md).
  float min_fitness = 0.55f;
  // A tracker's prior is centimetres off after a fix: the fine stage alone, from the prior, is
  // tried first, and its answer stands when it passes every gate having moved the sensor at most
  // fine_first_m (0: off); otherwise both stages run, as from any prior (docs/measurements.md: server time).
  // Only for priors no wider than fine_first_max_radius_m (api::Tracker's floor, 3 m: its sigma is
  // then at most 1 m): from a prior a metre off, the fine stage alone can settle in a local
  // minimum near it (riverside02 frame 115, a prior 7.8 m wide after 130 m without a fix: 1.06 m
  // off, docs/how-defaults-were-chosen.md), where both stages do not settle at all.
  float fine_first_m = 0.3f;
  float fine_first_max_radius_m = 3.0f;
  // The registered pose shifted along its weakest horizontal axis and across it, up to
  // ambiguity_range_m: where the query's segments find at least max_shifted_support times the
  // support they find at the pose, the objects say the vehicle is elsewhere (refused). True
  // answers reached at most 0.79 (riverside02), 0.69 (demo city), 0.24 (hku-mb); the one false
  // answer of the wrong-prior stress without this check, 2.8 (docs/how-defaults-were-chosen.md).
  float ambiguity_range_m = 12.0f;
  float max_shifted_support = 0.8f;
  // Of the segments that land on map segments, at least this many pass the matcher (as
  // RegistrationConfig::min_matched_segments). 2 answered riverside02 frame 37 (support 25,
  // true) but also frame 115, back from an unmapped street with a prior 7.8 m wide: 1.06 m off,
  // support 11, 2 matched, fitness 0.84, well constrained (docs/how-defaults-were-chosen.md).
  int min_matched_segments = 3;
  // ... and this many when the fine stage alone answered, moving the prior at most fine_first_m:
  // the tracker's prediction, an independent witness, then agrees with the scans. Frame 37 above
  // is such an answer (moved 0.03 m); frame 115 is not. Held without a false fix on riverside02,
  // hku-mb and the demo city, tracked and under wrong priors (docs/how-defaults-were-chosen.md).
  int min_matched_segments_near_prior = 2;
  // ... and also when at least this many query segments land on map segments under the pose
  // (twice RegistrationConfig::min_support): a layout of objects that dense, with no shifted pose
  // across the prior's diameter supported nearly as well, is the witness a narrow prior is
  // otherwise. riverside02 frame 37 under GNSS-like priors (sigma 10 m): support 25, 2 matched,
  // 0.05 m off, refused in every seed before; frame 115 above (support 11) stays refused.
  // Held without a false fix on riverside02, hku-mb and the demo city, tracked, under GNSS
  // priors and under wrong priors (docs/how-defaults-were-chosen.md). 0: off.
  int min_support_for_fewer_matched = 20;
  void validate() const;  // throws std::invalid_argument naming the field
};

// How a refined pose's covariance is made (pose_covariance): scale * s^2 * inverse(information),
// s the RMS point-to-plane residual, plus a floor. The ICP term alone is what independent point
// errors would give; neighbouring points' errors are correlated (the information of N points
// is far less than N independent ones: the scale), and errors the points cannot see remain:
// the map's own poses, the odometry's warp across the window (the floor). Both are calibrated
// on data (docs/how-defaults-were-chosen.md).
struct CovarianceConfig {
  float scale = 25.0f;
  float floor_m = 0.05f;   // standard deviation added on each position axis
  float floor_deg = 0.2f;  // ... and on each rotation axis
  void validate() const;
};

enum class RegistrationRefusal {
  kNone,          // accepted
  kWidePrior,     // the prior's radius exceeds max_prior_radius_m
  kFewPoints,     // fewer than min_query_points query points in the window, or no map points
  kNotConverged,  // the ICP was still moving after RefineConfig::max_iterations
  kLowFitness,    // the query points do not lie on the map's surfaces
  kHighRmse,      // ... not closely enough
  kOutsidePrior,  // the registered sensor left the prior's radius, or turned past its tolerance
  kDegenerate,    // some direction is not constrained
  kLowSupport,    // too few query segments land on (and match) map segments (the localizer's check)
  kAmbiguous,     // over a wide prior, registrations from distinct search peaks passed every gate
};

struct RegistrationResult {
  RegistrationRefusal refusal = RegistrationRefusal::kFewPoints;
  std::string reason;  // the refusal in words
  Pose3d T_map_query = Pose3d::Identity();
  float fitness = 0.0f, rmse_m = 0.0f;
  float weakest_axis_share = 0.0f;                         // see RegistrationConfig::min_axis_share
  Eigen::Vector3d weakest_axis = Eigen::Vector3d::Zero();  // its direction (map frame)
  Matrix6d covariance = Matrix6d::Zero();                  // see pose_covariance
  bool accepted() const { return refusal == RegistrationRefusal::kNone; }
};

// The 6x6 covariance of a refined pose: rotation (rad, about the map frame's axes, through
// `pivot`) then position of `pivot` (m, map frame), pivot being where RefineResult::information
// was taken (refine_alignment's pivot_target; the sensor). Zero if the information is singular.
Matrix6d pose_covariance(const RefineResult& refined, const CovarianceConfig& config);

// The translation information per correspondence along its weakest axis (rotation
// marginalised), and that axis.
float weakest_axis_share(const RefineResult& refined, Eigen::Vector3d* axis = nullptr);

// Registers query_points (query frame) to map_points (map frame) starting at T_map_query_prior.
// sensor_query: the sensor in the query frame (the window's centre; the covariance's pivot).
// The answer must stay within prior_radius_m and prior_rotation_deg of the prior.
// max_rmse_m: the localizer's RMS floor (LocalizerConfig::max_refine_rmse_voxels), 0: off.
RegistrationResult register_to_map(const PointCloud& query_points, const PointCloud& map_points,
                                   const Pose3d& T_map_query_prior, const Eigen::Vector3d& sensor_query,
                                   double prior_radius_m, double prior_rotation_deg, float max_rmse_m,
                                   const RegistrationConfig& config, const RefineConfig& refine,
                                   const CovarianceConfig& covariance = {});

}  // namespace segmatch
