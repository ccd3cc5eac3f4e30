// Matcher configuration, pair features and candidate filtering (paper III-D).
// The L2 baseline (paper IV-A, "L2") thresholds the feature distance; the random forest
// variants (RF_eigen, RF_eigen+shapes) are evaluated through RandomForestMatcher.
#include "segmatch/core/matching/matcher.h"
#include "segmatch/core/matching/retrieval.h"

#include "matching/match_features.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
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
  if (rf_min_samples <= 0) throw std::invalid_argument("MatcherConfig.rf_min_samples must be > 0");
}

int pair_feature_count(bool use_shapes) { return 3 * kEigenFeatureCount + (use_shapes ? kEsfHistograms : 0); }

namespace {
void check_descriptors(const Segment& s, bool use_shapes, const char* role) {
  if (!s.has_eigen)
    throw std::invalid_argument(std::string(role) + " segment " + std::to_string(s.id) + " has no eigen features");
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
    std::array<float, kEsfBins> q, t;
    detail::scale_esf(query.esf, q.data());
    detail::scale_esf(target.esf, t.data());
    detail::write_pair_features(query.eigen, target.eigen, q.data(), t.data(), out.data());
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
  // Checks first, in candidate order (the first bad candidate or descriptor throws), giving
  // every involved segment a slot for its scaled ESF (scale_esf), computed once per call.
  std::vector<int> q_slot(shapes ? queries.size() : 0, -1), t_slot(shapes ? targets.size() : 0, -1);
  std::vector<const Segment*> q_segs, t_segs;
  for (const Match& m : candidates) {
    check_candidate(m, queries, targets);
    const Segment& q = queries[m.query];
    const Segment& t = targets[m.target];
    if (!shapes) {
      check_descriptors(q, false, "query");
      check_descriptors(t, false, "target");
      continue;
    }
    if (q_slot[m.query] < 0) {
      check_descriptors(q, true, "query");
      q_slot[m.query] = static_cast<int>(q_segs.size());
      q_segs.push_back(&q);
    }
    if (t_slot[m.target] < 0) {
      check_descriptors(t, true, "target");
      t_slot[m.target] = static_cast<int>(t_segs.size());
      t_segs.push_back(&t);
    }
  }
  std::unique_ptr<float[]> q_esf(new float[q_segs.size() * kEsfBins]);
  std::unique_ptr<float[]> t_esf(new float[t_segs.size() * kEsfBins]);
  for (size_t i = 0; i < q_segs.size(); ++i) detail::scale_esf(q_segs[i]->esf, &q_esf[i * kEsfBins]);
  for (size_t i = 0; i < t_segs.size(); ++i) detail::scale_esf(t_segs[i]->esf, &t_esf[i * kEsfBins]);
  // Candidates go through in blocks: the block's pair rows stay in cache between being written
  // and the forest's walks, and the forest skips the rows that cannot reach the threshold.
  // Within a block the intersections are computed target by target (chains of the block's
  // rows per target slot, through `next`): the block's few query ESFs stay in L1 and each
  // target ESF (2.5 KB; ~250 of them per map neighbourhood overflow L2) is read once per
  // block rather than once per pair. The order in which rows are written does not change them.
  constexpr size_t kBlock = 1024;
  std::vector<float> rows(kBlock * dim), p(kBlock);
  std::vector<size_t> t_block(t_segs.size(), candidates.size());  // block a slot was last used in
  std::vector<int> t_head(t_segs.size(), -1), next(kBlock), touched;
  Matches out;
  for (size_t b0 = 0; b0 < candidates.size(); b0 += kBlock) {
    const size_t nb = std::min(kBlock, candidates.size() - b0);
    if (!shapes) {
      for (size_t j = 0; j < nb; ++j) {
        const Match& m = candidates[b0 + j];
        detail::write_pair_features(queries[m.query].eigen, targets[m.target].eigen, nullptr, nullptr,
                                    rows.data() + j * dim);
      }
    } else {
      touched.clear();
      for (size_t j = 0; j < nb; ++j) {
        const int ts = t_slot[candidates[b0 + j].target];
        if (t_block[ts] != b0) {
          t_block[ts] = b0;
          t_head[ts] = -1;
          touched.push_back(ts);
        }
        next[j] = t_head[ts];
        t_head[ts] = static_cast<int>(j);
      }
      for (int ts : touched) {
        const float* et = &t_esf[static_cast<size_t>(ts) * kEsfBins];
        for (int j = t_head[ts]; j >= 0; j = next[j]) {
          const Match& m = candidates[b0 + j];
          const float* eq = &q_esf[static_cast<size_t>(q_slot[m.query]) * kEsfBins];
          detail::write_pair_features(queries[m.query].eigen, targets[m.target].eigen, eq, et, rows.data() + j * dim);
        }
      }
    }
    rf.probabilities_at_least(rows.data(), nb, config.rf_threshold, p.data());
    for (size_t j = 0; j < nb; ++j) {
      const Match& m = candidates[b0 + j];
      if (p[j] >= config.rf_threshold) out.push_back({m.query, m.target, p[j]});
    }
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
    throw std::invalid_argument("filter_matches: MatcherConfig.use_shapes does not match the trained model");
  if (candidates.empty()) return {};
  return filter_rf(queries, targets, candidates, config, *rf);
}

}  // namespace segmatch
