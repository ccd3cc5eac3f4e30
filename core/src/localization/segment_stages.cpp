// The stages of a localization by segments (segment_stages.h). Private to the core.
#include "localization/segment_stages.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace segmatch {
namespace detail {
namespace {

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

Flow refused(LocalizationResult& r, Refusal why, std::string text) {
  r = refuse(std::move(r), why, std::move(text));
  return Flow::kRefused;
}

}  // namespace

LocalizationResult stopped(LocalizationResult r, const char* when) {
  return refuse(std::move(r), Refusal::kDeadlinePassed, std::string("the query's deadline passed ") + when);
}

double StageRunner::lap() {
  const auto now = std::chrono::steady_clock::now();
  const double ms = std::chrono::duration<double, std::milli>(now - last_).count();
  last_ = now;
  return ms;
}

LocalizationResult StageRunner::finish() {
  r_.timings.total_ms =
      before_ms_ + std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
  return std::move(r_);
}

// With a prior, registration onto the map around it answers first; segment matching is the
// fallback.
Flow register_first(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r) {
  register_near_prior(map.targets, map.points, map.centroids, map.classifier, map.config, *q.prior, q.sensor, r);
  if (r.localized()) return Flow::kAnswered;
  r.refine_fitness = r.refine_rmse_m = 0.0f;
  r.support = 0;
  r.inliers.clear();
  return Flow::kGoOn;
}

Flow enough_segments(const SegmentMap& map, LocalizationResult& r) {
  const int min_inliers = map.config.verification.min_inliers;
  if (r.query.size() >= static_cast<size_t>(min_inliers)) return Flow::kGoOn;
  return refused(r, Refusal::kTooFewSegments,
                 "only " + std::to_string(r.query.size()) + " segments in the query cloud (at least " +
                     std::to_string(min_inliers) + " needed)");
}

// Paper III-D: k-NN candidates in feature space (with a prior, among the map segments it
// allows) ...
Flow retrieve(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, SegmentWork& w) {
  w.candidates = q.prior ? retrieve_candidates_among(r.query, map.targets, map.index.scaling(),
                                                     targets_near_prior(r.query, map.targets, q.sensor, *q.prior),
                                                     map.config.retrieval)
                         : retrieve_candidates(r.query, map.index, map.config.retrieval);
  r.candidates = w.candidates.size();
  return Flow::kGoOn;
}

// ... then the classifier.
Flow classify(const SegmentMap& map, LocalizationResult& r, SegmentWork& w) {
  w.matches = filter_matches(r.query, map.targets, w.candidates, map.config.matcher, map.classifier);
  r.matches = w.matches.size();
  return Flow::kGoOn;
}

// Paper III-E: geometric verification on the segment centroids.
Flow verify(const SegmentMap& map, const Deadline& deadline, LocalizationResult& r, SegmentWork& w) {
  VerificationResult v = verify_matches(r.query, map.targets, w.matches, map.config.verification, deadline);
  if (!v.found)
    return refused(r, Refusal::kNoConsistentMatches,
                   "no geometrically consistent set of " + std::to_string(map.config.verification.min_inliers) +
                       " matches among " + std::to_string(w.matches.size()));
  w.hypotheses = std::move(v.hypotheses);
  return Flow::kGoOn;
}

Flow apply_prior(const SegmentQuery& q, LocalizationResult& r, SegmentWork& w) {
  const size_t verified = w.hypotheses.size();
  w.hypotheses = within_prior(std::move(w.hypotheses), q.sensor, q.prior);
  if (!w.hypotheses.empty()) return Flow::kGoOn;
  return refused(r, Refusal::kOutsidePrior,
                 "none of the " + std::to_string(verified) + " verified poses is within " +
                     std::to_string(q.prior->radius_m) + " m of the prior");
}

// Beyond the paper: the hypothesis that explains most of the query wins, if unambiguous.
Flow rank(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, SegmentWork& w) {
  const LocalizerConfig& c = map.config;
  w.ranked = rank_by_support(w.hypotheses, r.query, map.centroids, c.support_radius_m);
  const PoseHypothesis& best = w.hypotheses[w.ranked.best];
  r.hypotheses = w.hypotheses.size();
  r.support = w.ranked.support.count();
  r.runner_up_support = w.ranked.runner_up;
  r.inliers = best.inliers;
  r.T_map_query = best.T_target_query;
  const int min_support = floors_of(c, q.prior != nullptr).min_support;
  if (r.support < static_cast<size_t>(min_support))
    return refused(r, Refusal::kLowSupport,
                   "only " + std::to_string(r.support) + " query segments agree with the best pose (at least " +
                       std::to_string(min_support) + " needed)");
  if (static_cast<float>(r.runner_up_support) >= c.max_ambiguity * static_cast<float>(r.support))
    return refused(r, Refusal::kAmbiguous,
                   "ambiguous: two distinct poses are supported by " + std::to_string(r.support) + " and " +
                       std::to_string(r.runner_up_support) + " query segments");
  // With a prior, retrieval looked only where the prior puts each segment: a look-alike just
  // beyond it was never a hypothesis. A street of poles 6 m apart under a prior 6 m off and 3 m
  // wide was answered one pole off; the objects fit the truth as well (look_alike_beside).
  if (q.prior) {
    std::string beside = look_alike_beside(r.T_map_query, spread_axis(r.query, r.T_map_query), map.centroids, c,
                                           ambiguity_range_m(c, *q.prior), r);
    if (!beside.empty()) return refused(r, Refusal::kAmbiguous, "ambiguous within the prior: " + beside);
  }
  r.refine_fitness = 1.0f;
  return Flow::kGoOn;
}

// The pose refined on the supporting pairs' points, then on the recent window's.
Flow refine(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, const SegmentWork& w) {
  const LocalizerConfig& c = map.config;
  if (!c.refine_pose) return Flow::kGoOn;
  const float min_fitness = floors_of(c, q.prior != nullptr).min_fitness;
  const size_t stride = segment_point_stride(r.query, static_cast<size_t>(c.refine.max_segment_points));
  const PointCloud query_points = gather(r.query, w.ranked.support.pairs, true, stride);
  const PointCloud target_points = gather(map.targets, w.ranked.support.pairs, false, 1, map.points);
  const RefineResult refined =
      refine_alignment(query_points, target_points, r.T_map_query, c.refine, r.T_map_query * q.sensor.cast<double>());
  r.refine_fitness = refined.fitness;
  r.refine_rmse_m = refined.rmse_m;
  if (refined.fitness < min_fitness)
    return refused(r, Refusal::kSurfacesDisagree,
                   "matched segments' surfaces disagree (fitness " + std::to_string(refined.fitness) + ")");
  const float max_rmse_m = c.max_refine_rmse_voxels * c.segmentation.voxel.leaf_m;
  if (max_rmse_m > 0.0f && refined.rmse_m > max_rmse_m)
    return refused(r, Refusal::kSurfacesDisagree,
                   "matched segments' surfaces are " + std::to_string(refined.rmse_m) + " m apart (RMS, at most " +
                       std::to_string(max_rmse_m) + ")");
  r.T_map_query = refined.T_target_query;
  r.covariance = pose_covariance(refined, c.covariance);
  if (c.refine.recent_window_m > 0.0f)
    refine_recent_window(window_points(r.query, map.targets, map.points, q.sensor.cast<double>(), r.T_map_query, stride,
                                       c.refine.recent_window_m),
                         q.sensor, min_fitness, c.refine, c.covariance, r);
  return Flow::kGoOn;
}

Flow confidence(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r) {
  const Floors floors = floors_of(map.config, q.prior != nullptr);
  r.confidence = confidence_of(r.support, floors.min_support, r.refine_fitness);
  if (r.confidence < floors.min_confidence) {
    char why[96];
    std::snprintf(why, sizeof(why), "confidence %.2f below min_confidence %.2f", r.confidence, floors.min_confidence);
    return refused(r, Refusal::kLowConfidence, why);
  }
  r.status = LocalizationStatus::kLocalized;
  return Flow::kGoOn;
}

}  // namespace detail
}  // namespace segmatch
