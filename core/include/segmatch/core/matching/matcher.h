// Segment matching (paper section III-D): candidates from retrieval.h are accepted either by a
// hard L2 threshold in feature space (the paper's baseline) or by a random forest that
// "assigns a classification score w of being a match" followed by a threshold on w.
#pragma once

#include "segmatch/core/segmentation/segment.h"

#include <cstddef>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace segmatch {

enum class MatcherType { kL2, kRandomForest };

struct MatcherConfig {
  MatcherType type = MatcherType::kRandomForest;
  // Add the 10 ESF histogram intersections to the pair vector (paper: RF_eigen+shapes).
  bool use_shapes = true;
  // kL2: accept if the Euclidean distance between the z-scored eigen features (statistics of
  // the targets, see FeatureScaling) is below this. Normalised units: 1.0 = one standard
  // deviation of the map's features along one axis. The paper's 0.0024 (Table I) is on raw
  // features, so it does not transfer; 0.5 keeps near-duplicates (random pairs are ~3.7 apart).
  float l2_threshold = 0.5f;
  // kRandomForest: accept if the fraction of trees voting "same object" is >= this.
  // Paper Table I: 0.72 with shapes, 0.81 eigen only.
  float rf_threshold = 0.72f;
  int rf_trees = 25;  // paper Table I
  // Tree size. Deep trees (the authors' release used depth 25, 2 samples) memorise the
  // absolute features of the training objects and give unseen true pairs low votes: on a
  // held-out simulated city, true pairs voted 0.04 (median) with depth 25, 0.56 with depth 8
  // and 20 samples per split, and localization went from 0 to 13 of 13 revisit queries (see
  // the core issue's closing note). Shallow trees also classify faster.
  int rf_max_depth = 8;
  int rf_min_samples = 20;  // minimum samples in a node to split it further
  void validate() const;    // throws std::invalid_argument naming the field
  // Whether query segments must carry ESF histograms (the L2 matcher reads eigen features only).
  bool needs_esf() const { return type == MatcherType::kRandomForest && use_shapes; }
};

// Number of values in the pair vector: 21 (eigen only) or 31 (with shapes).
int pair_feature_count(bool use_shapes);

// Pair feature vector as in the paper: |f_q - f_t| (7), f_q (7), f_t (7), then with shapes the
// intersections of the 10 ESF histograms (each histogram normalised to sum 1 first, so the
// intersection is in [0, 1]). Throws std::invalid_argument if a segment lacks a needed
// descriptor.
std::vector<float> pair_features(const Segment& query, const Segment& target, bool use_shapes);

class RandomForestMatcher {
 public:
  explicit RandomForestMatcher(const MatcherConfig& config = {});
  ~RandomForestMatcher();
  RandomForestMatcher(RandomForestMatcher&&) noexcept;
  RandomForestMatcher& operator=(RandomForestMatcher&&) noexcept;
  RandomForestMatcher(const RandomForestMatcher&) = delete;
  RandomForestMatcher& operator=(const RandomForestMatcher&) = delete;

  // Trains on labelled pairs (query, target), true = same object. Throws std::invalid_argument
  // if the sizes differ, a pointer is null, or there are no positives or no negatives.
  void train(const std::vector<std::pair<const Segment*, const Segment*>>& pairs, const std::vector<bool>& same_object);
  bool trained() const;
  // Fraction of trees voting "same object", in [0, 1]. Throws std::logic_error if untrained.
  float probability(const Segment& query, const Segment& target) const;
  // Batch version over pair feature rows (rows x pair_feature_count(config().use_shapes)).
  std::vector<float> probabilities(const std::vector<float>& rows) const;
  // Same over the n rows at `rows` into out[0..n), but exact only where the probability is
  // >= min_probability; the other rows get -1. The forest stops walking a row once too many
  // trees voted "different" for it to reach min_probability (filter_matches() keeps only
  // probabilities >= rf_threshold, and most candidates are far below it).
  void probabilities_at_least(const float* rows, size_t n, float min_probability, float* out) const;
  // Same through OpenCV's own RTrees::getVotes (slow; reference for tests).
  std::vector<float> opencv_probabilities(const std::vector<float>& rows) const;

  // Model bytes: OpenCV FileStorage YAML in memory with a format tag, version and the
  // use_shapes flag. Throws std::logic_error if untrained.
  std::string save() const;
  // Throws std::runtime_error with a clear message on garbage, a wrong format or version.
  static RandomForestMatcher load(const std::string& bytes);
  const MatcherConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Keeps the candidates that pass the matcher, in input order:
//   kL2: distance in normalised eigen space (FeatureScaling::fit(targets)) < l2_threshold,
//        score = 1 / (1 + distance);
//   kRandomForest: probability >= rf_threshold, score = probability. rf must be trained and
//        built with the same use_shapes (std::invalid_argument otherwise); rf may be null for kL2.
Matches filter_matches(const Segments& queries, const Segments& targets, const Matches& candidates,
                       const MatcherConfig& config, const RandomForestMatcher* rf);

}  // namespace segmatch
