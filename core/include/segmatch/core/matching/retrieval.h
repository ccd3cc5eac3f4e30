// Candidate retrieval (paper section III-D): "we first retrieve candidate matches by
// performing a k-d tree search in the feature space, which are then fed to the classifier".
// Section IV-A uses the k = 200 nearest neighbours in the target map.
#pragma once

#include "segmatch/core/segmentation/segment.h"

#include <memory>
#include <utility>
#include <vector>

namespace segmatch {

struct RetrievalConfig {
  int k = 200;            // neighbours per query segment (paper IV-A: 200)
  void validate() const;  // throws std::invalid_argument naming the field
};

// Per-dimension z-score scaling of the eigen features. The statistics come from the target
// (map) segments, so queries are scaled exactly like the targets they are compared to.
struct FeatureScaling {
  EigenFeatures mean{};                        // per-dimension mean over the targets
  EigenFeatures inv_std{1, 1, 1, 1, 1, 1, 1};  // 1 / max(standard deviation, 0.01)

  // Statistics of the targets' eigen features (identity scaling for an empty set).
  static FeatureScaling fit(const Segments& targets);
  EigenFeatures apply(const EigenFeatures& f) const;
  // Euclidean distance between two features in normalised units.
  float distance(const EigenFeatures& a, const EigenFeatures& b) const;
};

// Exact k-d tree (FLANN KDTreeSingleIndex) over the targets' normalised eigen features.
class FeatureIndex {
 public:
  FeatureIndex();
  ~FeatureIndex();
  FeatureIndex(FeatureIndex&&) noexcept;
  FeatureIndex& operator=(FeatureIndex&&) noexcept;
  FeatureIndex(const FeatureIndex&) = delete;
  FeatureIndex& operator=(const FeatureIndex&) = delete;

  // (Re)builds the index. Throws std::invalid_argument if a target has no eigen features.
  void build(const Segments& targets);
  // k nearest target indices with squared distances in normalised space, nearest first;
  // k is clipped to size(). Exact search. Empty if the index is empty or k <= 0.
  std::vector<std::pair<int, float>> knn(const EigenFeatures& f, int k) const;
  size_t size() const;
  const FeatureScaling& scaling() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Candidate pairs: for each query segment its k nearest targets, score = -distance
// (Euclidean, normalised units), ordered by query then nearest first.
// Throws std::invalid_argument if a query has no eigen features.
Matches retrieve_candidates(const Segments& queries, const FeatureIndex& index, const RetrievalConfig& config);

// The same restricted to allowed targets: for each query segment qi, its k nearest (in the
// index's normalised feature space) among the targets t with allowed(qi, t), by brute force.
// For a search narrowed by a pose prior, where the allowed targets are a few hundred of a map
// of any size (Localizer with a PosePrior). Same output order and scores as above.
Matches retrieve_candidates_among(const Segments& queries, const Segments& targets, const FeatureScaling& scaling,
                                  const std::vector<std::vector<int>>& allowed, const RetrievalConfig& config);

}  // namespace segmatch
