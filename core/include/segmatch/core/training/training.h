// Labelled segment pairs for training the match classifier from ground truth (paper IV-B:
// for each query segment, its k nearest target segments in feature space are candidate
// pairs; pairs of the same object are positives, the others negatives, kept at 1:50).
#pragma once

#include "segmatch/core/matching/retrieval.h"
#include "segmatch/core/segmentation/segment.h"

#include <utility>
#include <vector>

namespace segmatch {

struct TrainingPairConfig {
  int k = 200;                      // candidates per query segment
  int negatives_per_positive = 50;  // paper: 1:50
  uint64_t seed = 7;                // which negatives are kept
  // Positives must also have centroids this close (both sets in one frame, e.g. world
  // ground truth): one building is one instance but yields facade pieces of different shape
  // from different places, and calling those "the same" teaches the classifier noise.
  // Same-instance pairs farther apart are left out (neither positive nor negative).
  // 0 disables the check.
  float max_centroid_distance_m = 1.5f;
  // label_pairs_by_distance() only (real data, no instance ids): candidates whose centroids
  // are farther apart than this are negatives; between max_centroid_distance_m and this the
  // pair is ambiguous (a neighbouring piece of the same object, or a pose error) and left out.
  float min_negative_distance_m = 4.0f;
  void validate() const;
};

struct TrainingPairs {
  std::vector<std::pair<const Segment*, const Segment*>> pairs;  // (query, target)
  std::vector<bool> same_object;
  size_t positives = 0, negatives = 0;
};

// Segments are the same object when their labels carry the same non-zero instance id
// (Segment::label, SemanticKITTI encoding) and their centroids are within
// max_centroid_distance_m. Segments with instance 0 (ground, unknown) give no pairs. Pointers refer into `queries` and
// `targets`, which must outlive the result.
TrainingPairs label_pairs_by_instance(const Segments& queries, const Segments& targets, const FeatureIndex& index,
                                      const TrainingPairConfig& config);

// Real data (paper IV-B on KITTI): queries and targets already in one frame by the ground-truth
// poses; a candidate is positive when the centroids are within max_centroid_distance_m,
// negative beyond min_negative_distance_m, left out in between. Same k-NN candidates and 1:N
// negative subsampling as label_pairs_by_instance().
TrainingPairs label_pairs_by_distance(const Segments& queries, const Segments& targets, const FeatureIndex& index,
                                      const TrainingPairConfig& config);

}  // namespace segmatch
