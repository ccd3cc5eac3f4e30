// Geometric verification (paper section III-E) and pose refinement (beyond the paper).
//
// Paper: candidate matches are tested for geometric consistency on the segment centroids
// (RANSAC resolution 0.4 m, minimum cluster size 4, Table I), "resulting in a 6DOF
// transformation and a list of matching segments". Here the consistent cluster is the largest
// set of candidates whose pairwise centroid distances agree between query and target (a
// clique in the consistency graph, found greedily and deterministically), then the transform
// is the least-squares rigid fit on the clique's centroids.
//
// T_target_query maps query-frame points into the target (map) frame.
#pragma once

#include "segmatch/core/common/deadline.h"
#include "segmatch/core/common/types.h"
#include "segmatch/core/segmentation/segment.h"

#include <cstdint>

namespace segmatch {

struct VerificationConfig {
  // Two matches are consistent if the distance between their query centroids and the distance
  // between their target centroids differ by less than this (paper Table I: 0.4 m).
  float resolution_m = 0.4f;
  int min_inliers = 4;  // paper Table I: minimum cluster size 4
  // Maximum number of seed matches grown into a consistent cluster. With at most this many
  // candidates every candidate is a seed (exhaustive, no randomness); beyond it the seeds are
  // the most-connected candidates plus a random sample drawn with `seed`.
  int max_iterations = 2000;
  uint64_t seed = 42;
  // Beyond the paper: up to this many distinct transforms (largest cluster first) are kept as
  // hypotheses. In a street of evenly spaced poles or trees a shifted copy of the true
  // cluster is also consistent; the caller ranks hypotheses with evidence beyond the matches
  // (see Localizer). Two hypotheses are distinct if they move the centre of the query's
  // matched centroids apart by more than distinct_translation_m, or differ in rotation by
  // more than distinct_rotation_deg (slightly different fits of one place are not distinct).
  int max_hypotheses = 8;
  float distinct_translation_m = 2.0f;
  float distinct_rotation_deg = 5.0f;
  // Beyond the paper, a resource bound: with more candidates than this, only this many with the
  // highest scores are verified (in their order). The consistency graph takes n^2 bits, so a
  // query built to match everything (a forest of identical poles) could otherwise make a
  // server allocate gigabytes; 30,000 candidates take 112 MB. docs/how-defaults-were-chosen.md has the counts real
  // queries reach. 0 = no bound.
  int max_candidates = 30000;
  void validate() const;  // throws std::invalid_argument naming the field
};

struct PoseHypothesis {
  Pose3d T_target_query = Pose3d::Identity();  // Umeyama (rigid, no scale) on inlier centroids
  Matches inliers;                             // in candidate order
  float inlier_rmse_m = 0;                     // centroid residual after the fit
};

struct VerificationResult {
  bool found = false;
  Pose3d T_target_query = Pose3d::Identity();  // the largest cluster's transform
  Matches inliers;                             // in candidate order
  float inlier_rmse_m = 0;                     // centroid residual after the fit
  std::vector<PoseHypothesis> hypotheses;      // distinct clusters, largest first (first = above)
};

// Largest set of mutually consistent candidate matches (one-to-one: no two share a query or a
// target segment), then the transform. found = false if fewer than min_inliers remain after
// dropping members whose residual under the fitted transform exceeds resolution_m. The other
// distinct clusters of at least min_inliers are returned as further hypotheses.
// Once `deadline` has passed (checked while the consistency graph is built and between seeds,
// the O(n^2) part), it gives up: found = false, and the caller sees the deadline passed.
VerificationResult verify_matches(const Segments& queries, const Segments& targets, const Matches& candidates,
                                  const VerificationConfig& config, const Deadline& deadline = {});

struct RefineConfig {
  int max_iterations = 30;
  // Query points farther than this from their nearest target point (after applying the
  // current estimate) are ignored. 0.5 m is above the expected error left by verification on
  // centroids (decimetres) and below typical object separation.
  float max_correspondence_m = 0.5f;
  // Stop when an iteration moves the estimate by less than this (translation in metres;
  // rotation in radians, i.e. the displacement of a point 1 m from the origin).
  float convergence_m = 1e-4f;
  bool point_to_plane = true;  // point-to-plane (normals from target neighbourhoods) or point-to-point
  // The query cloud is subsampled (deterministic stride) to at most this many points to keep
  // refinement within ~20 ms; the target cloud is always used in full.
  int max_query_points = 2000;
  // Before that, each matched query segment gives every s-th of its points, s the same for all
  // segments of the query and the smallest that leaves at most this many points in the whole
  // query (0 = every point). It changes little for refinement (which then samples 2000 of
  // them), but a vehicle that segments its own cloud makes the very same cut before sending
  // its segments (docs/protocol.md 5.5): both paths refine on the same points, and the request
  // stays a few hundred kilobytes (a 60 m HDL-64E cylinder has ~110k points in its segments).
  int max_segment_points = 20000;
  // The answer is the sensor's pose now, not the whole local cloud's (beyond the paper): the
  // vehicle's odometry built the cloud and drifts along it, so the pose that best aligns all of
  // it is off at the sensor by the drift accumulated over the window. After the whole-cloud
  // refinement the query segments' points within recent_window_m (horizontal) of the sensor
  // are refined alone against the map segments there, starting from the whole cloud's pose;
  // with fewer than min_recent_points of them, or a fitness below the floor, the whole-cloud
  // pose stands. 0: off.
  float recent_window_m = 30.0f;
  int min_recent_points = 200;
  void validate() const;  // throws std::invalid_argument naming the field
};

struct RefineResult {
  Pose3d T_target_query = Pose3d::Identity();
  bool converged = false;
  int iterations = 0;
  float rmse_m = 0;   // point-to-point RMSE of the correspondences within max_correspondence_m
  float fitness = 0;  // fraction of (used) query points with a target neighbour within max_correspondence_m
  // How far the last iteration moved the estimate (translation plus rotation in radians, as
  // convergence_m): small when the loop ended settled, whether or not below convergence_m.
  float last_step_m = 0;
  // Point-to-plane only, at the returned pose: the Gauss-Newton information sum J J^T over the
  // correspondences with a normal, J = [(p - pivot) x n, n] (a rotation about the pivot, then a
  // translation, both in the target frame), their number and RMS residual n . (p - q). It is
  // what a covariance and a degeneracy check are made from (registration.h).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  size_t plane_correspondences = 0;
  float plane_rmse_m = 0;
};

// ICP of the query points onto the target points starting at `initial` (T_target_query).
// With fewer than 6 correspondences the result keeps the last estimate, converged = false.
// pivot_target: where RefineResult::information is taken (target frame; e.g. the sensor).
RefineResult refine_alignment(const PointCloud& query_points, const PointCloud& target_points, const Pose3d& initial,
                              const RefineConfig& config,
                              const Eigen::Vector3d& pivot_target = Eigen::Vector3d::Zero());

}  // namespace segmatch
