// Matcher configuration, pair features and candidate filtering (paper III-D).
// The L2 baseline (paper IV-A, "L2") thresholds the feature distance; the random forest
// variants (RF_eigen, RF_eigen+shapes) are evaluated through RandomForestMatcher.
#include "segmatch/core/matcher.h"
#include "segmatch/core/retrieval.h"

#include "match_features.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch {

void MatcherConfig::validate() const {
  if (!(l2_threshold > 0.f) || !std::isfinite(l2_threshold))
    throw std::invalid_argument("MatcherConfig.l2_threshold must be finite and > 0");
  if (!(rf_threshold >= 0.f && rf_threshold <= 1.f))
    throw std::invalid_argument("MatcherConfig.rf_threshold must be in [0, 1]");
  if (rf_trees <= 0) throw std::invalid_argument("MatcherConfig.rf_trees must be > 0");
  if (rf_max_depth <= 0) throw std::invalid_argument("MatcherConfig.rf_max_depth must be > 0");
  if (rf_min_samples <= 0)
    throw std::invalid_argument("MatcherConfig.rf_min_samples must be > 0");
}

int pair_feature_count(bool use_shapes) {
  return 3 * kEigenFeatureCount + (use_shapes ? kEsfHistograms : 0);
}

namespace {
void check_descriptors(const Segment& s, bool use_shapes, const char* role) {
  if (!s.has_eigen)
    throw std::invalid_argument(std::string(role) + " segment " + std::to_string(s.id) +
                                " has no eigen features");
  if (use_shapes && !s.has_esf)
    throw std::invalid_argument(std::string(role) + " segment " + std::to_string(s.id) +
                                " has no ESF descriptor (use_shapes = true)");
}
}  // namespace

std::vector<float> pair_features(const Segment& query, const Segment& target, bool use_shapes) {
  check_descriptors(query, use_shapes, "query");
  check_descriptors(target, use_shapes, "target");
  std::vector<float> out(pair_feature_count(use_shapes));
  if (use_shapes) {
    const detail::ScaledEsf q = detail::scaled_esf(query.esf);
    const detail::ScaledEsf t = detail::scaled_esf(target.esf);
    detail::write_pair_features(query.eigen, target.eigen, &q, &t, out.data());
  } else {
    detail::write_pair_features(query.eigen, target.eigen, nullptr, nullptr, out.data());
  }
  return out;
}

namespace {

void check_candidate(const Match& m, const Segments& queries, const Segments& targets) {
  if (m.query < 0 || m.query >= static_cast<int>(queries.size()) || m.target < 0 ||
      m.target >= static_cast<int>(targets.size()))
    throw std::invalid_argument("filter_matches: candidate index out of range");
}

Matches filter_l2(const Segments& queries, const Segments& targets, const Matches& candidates,
                  const MatcherConfig& config) {
  const FeatureScaling scaling = FeatureScaling::fit(targets);
  Matches out;
  for (const Match& m : candidates) {
    check_candidate(m, queries, targets);
    check_descriptors(queries[m.query], false, "query");
    check_descriptors(targets[m.target], false, "target");
    const float d = scaling.distance(queries[m.query].eigen, targets[m.target].eigen);
    if (d < config.l2_threshold) out.push_back({m.query, m.target, 1.f / (1.f + d)});
  }
  return out;
}

Matches filter_rf(const Segments& queries, const Segments& targets, const Matches& candidates,
                  const MatcherConfig& config, const RandomForestMatcher& rf) {
  const bool shapes = config.use_shapes;
  const int dim = pair_feature_count(shapes);
  // Histogram scales of every involved ESF, once rather than once per pair.
  std::vector<int> q_slot, t_slot;
  std::vector<detail::ScaledEsf> q_esf, t_esf;
  if (shapes) {
    q_slot.assign(queries.size(), -1);
    t_slot.assign(targets.size(), -1);
  }
  std::vector<float> rows(candidates.size() * dim);
  for (size_t i = 0; i < candidates.size(); ++i) {
    const Match& m = candidates[i];
    check_candidate(m, queries, targets);
    const Segment& q = queries[m.query];
    const Segment& t = targets[m.target];
    const detail::ScaledEsf* eq = nullptr;
    const detail::ScaledEsf* et = nullptr;
    if (shapes) {
      if (q_slot[m.query] < 0) {
        check_descriptors(q, true, "query");
        q_slot[m.query] = static_cast<int>(q_esf.size());
        q_esf.push_back(detail::scaled_esf(q.esf));
      }
      if (t_slot[m.target] < 0) {
        check_descriptors(t, true, "target");
        t_slot[m.target] = static_cast<int>(t_esf.size());
        t_esf.push_back(detail::scaled_esf(t.esf));
      }
      eq = &q_esf[q_slot[m.query]];
      et = &t_esf[t_slot[m.target]];
    } else {
      check_descriptors(q, false, "query");
      check_descriptors(t, false, "target");
    }
    detail::write_pair_features(q.eigen, t.eigen, eq, et, rows.data() + i * dim);
  }
  const std::vector<float> p = rf.probabilities(rows);
  Matches out;
  for (size_t i = 0; i < candidates.size(); ++i) {
    if (p[i] >= config.rf_threshold) out.push_back({candidates[i].query, candidates[i].target, p[i]});
  }
  return out;
}

}  // namespace

Matches filter_matches(const Segments& queries, const Segments& targets, const Matches& candidates,
                       const MatcherConfig& config, const RandomForestMatcher* rf) {
  config.validate();
  if (config.type == MatcherType::kL2) return filter_l2(queries, targets, candidates, config);
  if (rf == nullptr || !rf->trained())
    throw std::invalid_argument("filter_matches: kRandomForest needs a trained RandomForestMatcher");
  if (rf->config().use_shapes != config.use_shapes)
    throw std::invalid_argument(
        "filter_matches: MatcherConfig.use_shapes does not match the trained model");
  if (candidates.empty()) return {};
  return filter_rf(queries, targets, candidates, config, *rf);
}

}  // namespace segmatch
