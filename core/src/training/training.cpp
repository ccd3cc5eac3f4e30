#include "segmatch/core/training/training.h"

#include "segmatch/core/detail/random.h"

#include <stdexcept>

namespace segmatch {

void TrainingPairConfig::validate() const {
  if (k < 1) throw std::invalid_argument("k must be at least 1");
  if (negatives_per_positive < 1) throw std::invalid_argument("negatives_per_positive must be at least 1");
  if (!(max_centroid_distance_m >= 0.f)) throw std::invalid_argument("max_centroid_distance_m must be >= 0");
  if (!(min_negative_distance_m >= max_centroid_distance_m))
    throw std::invalid_argument("min_negative_distance_m must be >= max_centroid_distance_m");
}

namespace {

// Appends a random subset of the negatives at the configured ratio (deterministic by seed).
void keep_negatives(const Segments& queries, const Segments& targets, std::vector<std::pair<int, int>>& negatives,
                    const TrainingPairConfig& config, TrainingPairs& out) {
  Rng rng(config.seed);
  const size_t keep = std::min(negatives.size(), out.positives * static_cast<size_t>(config.negatives_per_positive));
  for (size_t i = 0; i < keep; ++i) {
    const size_t j = i + rng.index(negatives.size() - i);
    std::swap(negatives[i], negatives[j]);
    out.pairs.emplace_back(&queries[negatives[i].first], &targets[negatives[i].second]);
    out.same_object.push_back(false);
    ++out.negatives;
  }
}

enum class PairLabel { kPositive, kNegative, kLeftOut };

// Paper IV-B: each query segment's k nearest targets in feature space are its candidates, the
// only pairs the classifier sees at run time (taking positives from anywhere would teach it
// that pairs far apart in feature space are the same object); label(q, t) says what each is.
template <typename Label>
TrainingPairs label_candidates(const Segments& queries, const Segments& targets, const FeatureIndex& index,
                               const TrainingPairConfig& config, Label label) {
  config.validate();
  TrainingPairs out;
  std::vector<std::pair<int, int>> negatives;
  for (size_t q = 0; q < queries.size(); ++q) {
    for (const auto& [t, dist] : index.knn(queries[q].eigen, config.k)) {
      const PairLabel l = label(queries[q], targets[t]);
      if (l == PairLabel::kPositive) {
        out.pairs.emplace_back(&queries[q], &targets[t]);
        out.same_object.push_back(true);
        ++out.positives;
      } else if (l == PairLabel::kNegative) {
        negatives.emplace_back(static_cast<int>(q), t);
      }
    }
  }
  keep_negatives(queries, targets, negatives, config, out);
  return out;
}

}  // namespace

TrainingPairs label_pairs_by_instance(const Segments& queries, const Segments& targets, const FeatureIndex& index,
                                      const TrainingPairConfig& config) {
  return label_candidates(queries, targets, index, config, [&](const Segment& q, const Segment& t) {
    const uint16_t inst = label_instance(q.label), other = label_instance(t.label);
    if (inst == 0 || other == 0) return PairLabel::kLeftOut;  // ground, unknown
    if (other != inst) return PairLabel::kNegative;
    if (config.max_centroid_distance_m > 0.f && (q.centroid - t.centroid).norm() > config.max_centroid_distance_m)
      return PairLabel::kLeftOut;  // same object, different part: ambiguous
    return PairLabel::kPositive;
  });
}

TrainingPairs label_pairs_by_distance(const Segments& queries, const Segments& targets, const FeatureIndex& index,
                                      const TrainingPairConfig& config) {
  return label_candidates(queries, targets, index, config, [&](const Segment& q, const Segment& t) {
    const float d = (q.centroid - t.centroid).norm();
    if (d <= config.max_centroid_distance_m) return PairLabel::kPositive;
    return d > config.min_negative_distance_m ? PairLabel::kNegative : PairLabel::kLeftOut;
  });
}

}  // namespace segmatch
