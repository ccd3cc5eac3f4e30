// Pictures of an evaluation (PNG, OpenCV): the trajectory with correct and false
// localizations, the P(x) curve of equation 1, the error histogram, and ROC curves.
#pragma once

#include <segmatch/eval/metrics.h>

#include <string>
#include <vector>

namespace segmatch {
namespace eval {

// Top-down, map frame: the map's trajectory (grey), the query's true path (light blue),
// correct localizations (green), false ones (red, joined to the true position), queries
// that were not localized (small dark dots). Throws std::runtime_error when it cannot write.
void plot_trajectory(const std::string& png, const std::vector<Eigen::Vector3d>& map_trajectory,
                     const std::vector<QueryOutcome>& outcomes, const std::string& title);
// P(x) against x, with x95 marked.
void plot_px(const std::string& png, const PxCurve& curve, const std::string& title);
// Histogram of the translation errors of correct localizations (centimetres).
void plot_error_histogram(const std::string& png, const std::vector<QueryOutcome>& outcomes, const std::string& title);

struct RocCurve {
  std::string name;
  std::vector<double> fpr, tpr;                 // from (0, 0) to (1, 1)
  double operating_fpr = 0, operating_tpr = 0;  // marked with a dot
  double operating_threshold = 0;               // score threshold of the operating point
  double auc = 0;                               // area under the curve
};
void plot_roc(const std::string& png, const std::vector<RocCurve>& curves, const std::string& title);

}  // namespace eval
}  // namespace segmatch
