// Where true matches are lost (segmatch-eval funnel): for every query of a replay, its query
// segments are put into the map frame with the ground truth and counted stage by stage, in the
// order of the paper's pipeline (III-C, III-D):
//   segments      query segments extracted
//   counterpart   those with a map segment centroid within counterpart_radius_m under the truth
//                 (segmentation and the map agree there is one object)
//   retrieved     those whose counterpart is among their k nearest neighbours in feature space
//   classified    those whose counterpart pair also passes the matcher (RF or L2)
// A query needs >= verification.min_inliers classified true pairs to have a chance.
#pragma once

#include <segmatch/core/localization/localizer.h>
#include <segmatch/eval/localization_run.h>

#include <string>
#include <vector>

namespace segmatch {
namespace eval {

struct FunnelQuery {
  size_t frame = 0;
  double odometer_m = 0.0;
  size_t segments = 0, counterpart = 0, retrieved = 0, classified = 0;
  size_t candidates = 0, matches = 0;  // all candidate pairs and all pairs passing the matcher
};

struct FunnelConfig {
  float counterpart_radius_m = 1.0f;
};

// Replays config's query sequence against `localizer` (the map's, as served) and counts.
std::vector<FunnelQuery> run_funnel(const LocalizationRunConfig& config, const Localizer& localizer,
                                    const FunnelConfig& funnel = {});
// One line per query and the totals.
void print_funnel(const std::vector<FunnelQuery>& queries, int min_inliers);

}  // namespace eval
}  // namespace segmatch
