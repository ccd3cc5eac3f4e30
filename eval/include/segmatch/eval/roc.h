// ROC curves of segment-match classifiers (paper Fig. 3): a score per labelled candidate pair,
// higher = more likely the same object.
#pragma once

#include <segmatch/eval/plots.h>

#include <string>
#include <vector>

namespace segmatch {
namespace eval {

struct ScoredPair {
  double score = 0;
  bool positive = false;
};

// The curve over every distinct threshold, its AUC, and the operating point: the highest TPR
// whose FPR does not exceed max_fpr (paper: operating points at FPR 0.2). Throws
// std::invalid_argument without positives or negatives.
RocCurve roc_curve(const std::string& name, std::vector<ScoredPair> pairs, double max_fpr = 0.2);

}  // namespace eval
}  // namespace segmatch
