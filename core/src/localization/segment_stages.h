// The stages of a localization by segments (Localizer::localize_segments), one function each in
// the paper's order: retrieve (III-D), classify (III-D), verify (III-E), then beyond the paper
// the prior, ranking by support, refinement and confidence. Each fills the result and says
// whether the query goes on; a stage that ends it has refused the result with a typed reason
// (or, registration near a prior, answered it). Deadlines and timings live in StageRunner, not
// in the stages. Private to the core.
#pragma once

#include "localization/localizer_stages.h"

#include "segmatch/core/matching/matcher.h"

#include <chrono>
#include <vector>

namespace segmatch {
namespace detail {

// What the stages read of the map: the Localizer's members.
struct SegmentMap {
  const LocalizerConfig& config;
  const Segments& targets;
  const FeatureIndex& index;
  const CentroidIndex& centroids;
  const RandomForestMatcher* classifier;
  const TargetPoints* points;
};

// What the query brings besides its segments (in the result).
struct SegmentQuery {
  Eigen::Vector3f sensor;  // query frame
  const PosePrior* prior;  // null: global
};

// What one stage hands the next.
struct SegmentWork {
  Matches candidates, matches;
  std::vector<PoseHypothesis> hypotheses;
  Ranked ranked;
};

enum class Flow { kGoOn, kAnswered, kRefused };

Flow register_first(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r);
Flow enough_segments(const SegmentMap& map, LocalizationResult& r);
Flow retrieve(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, SegmentWork& w);
Flow classify(const SegmentMap& map, LocalizationResult& r, SegmentWork& w);
Flow verify(const SegmentMap& map, const Deadline& deadline, LocalizationResult& r, SegmentWork& w);
Flow apply_prior(const SegmentQuery& q, LocalizationResult& r, SegmentWork& w);
Flow rank(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, SegmentWork& w);
Flow refine(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r, const SegmentWork& w);
Flow confidence(const SegmentMap& map, const SegmentQuery& q, LocalizationResult& r);

LocalizationResult stopped(LocalizationResult r, const char* when);

// Runs the stages of one query: each stage's time goes to its module, and the query stops
// (Refusal::kDeadlinePassed, "during <stage>") when the deadline passed during a stage that
// did not answer.
class StageRunner {
 public:
  StageRunner(LocalizationResult& r, const Deadline& deadline)
      : r_(r), deadline_(deadline), before_ms_(r.timings.total_ms) {}

  // False when the query ends here (r is then final). module: where the stage's time counts
  // (null: nowhere); during: the stage's name for a deadline refusal (null: not checked).
  template <typename Stage>
  bool operator()(double ModuleTimings::*module, const char* during, Stage&& stage) {
    const Flow flow = stage();
    const double ms = lap();
    if (module) r_.timings.*module += ms;
    if (flow == Flow::kAnswered) return false;
    if (during && deadline_.passed()) {
      r_ = stopped(std::move(r_), during);
      return false;
    }
    return flow == Flow::kGoOn;
  }
  // The result with its total time (the caller's segmentation, if any, included).
  LocalizationResult finish();

 private:
  double lap();

  LocalizationResult& r_;
  const Deadline& deadline_;
  double before_ms_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now(), last_ = start_;
};

}  // namespace detail
}  // namespace segmatch
