#include "segmatch/eval/roc.h"

#include <algorithm>
#include <stdexcept>

namespace segmatch {
namespace eval {

RocCurve roc_curve(const std::string& name, std::vector<ScoredPair> pairs, double max_fpr) {
  size_t positives = 0;
  for (const ScoredPair& p : pairs) positives += p.positive;
  const size_t negatives = pairs.size() - positives;
  if (positives == 0 || negatives == 0) throw std::invalid_argument("roc_curve: needs positive and negative pairs");
  std::sort(pairs.begin(), pairs.end(), [](const ScoredPair& a, const ScoredPair& b) { return a.score > b.score; });
  RocCurve c;
  c.name = name;
  c.fpr.push_back(0);
  c.tpr.push_back(0);
  c.operating_threshold = pairs.front().score + 1.0;
  size_t tp = 0, fp = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    (pairs[i].positive ? tp : fp) += 1;
    // One point per distinct score: pairs of equal score are accepted together.
    if (i + 1 < pairs.size() && pairs[i + 1].score == pairs[i].score) continue;
    const double fpr = double(fp) / negatives, tpr = double(tp) / positives;
    c.auc += (fpr - c.fpr.back()) * (tpr + c.tpr.back()) / 2;
    c.fpr.push_back(fpr);
    c.tpr.push_back(tpr);
    if (fpr <= max_fpr) {
      c.operating_fpr = fpr;
      c.operating_tpr = tpr;
      c.operating_threshold = pairs[i].score;
    }
  }
  return c;
}

}  // namespace eval
}  // namespace segmatch
