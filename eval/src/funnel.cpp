#include "segmatch/eval/funnel.h"
#include "segmatch/eval/localization_run.h"

#include "segmatch/core/verification/support.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/io/replay.h"
#include "segmatch/io/sequence.h"

#include <cstdio>
#include <set>
#include <utility>

namespace segmatch {
namespace eval {

std::vector<FunnelQuery> run_funnel(const LocalizationRunConfig& c, const Localizer& localizer,
                                    const FunnelConfig& funnel) {
  const Truth opened = open_truth(c);
  const Poses& truth = opened.T_map_sensor;
  const std::string folder = opened.sequence.folder();
  // The local clouds as a vehicle builds them: from its odometry (or the reference, to compare).
  io::SequenceOptions so;
  if (c.cloud_poses == io::CloudPoses::kOdometry) so.poses_path = io::odometry_poses_path(folder, c.odometry_path);
  const io::Sequence sequence = io::Sequence::open(folder, so);
  std::printf("local clouds: %s\n", c.cloud_poses == io::CloudPoses::kOdometry
                                        ? so.poses_path.c_str()
                                        : "the REFERENCE poses (a comparison only)");
  const LocalizerConfig& lc = localizer.config();
  const Segments& targets = localizer.targets();
  const CentroidIndex centroids(targets, funnel.counterpart_radius_m);
  io::ReplayConfig replay = c.replay;
  std::vector<FunnelQuery> out;
  io::replay_sequence(sequence, replay, [&](const io::ReplayQuery& q) {
    FunnelQuery f;
    f.frame = q.frame;
    f.odometer_m = q.odometer_m;
    const Eigen::Vector3f sensor = q.T_odom_sensor.translation().cast<float>();
    const Segments query = q.voxelized ? extract_segments_from_voxels(q.cloud_odom, sensor, lc.segmentation)
                                       : extract_segments(q.cloud_odom, sensor, lc.segmentation);
    f.segments = query.size();
    const Pose3d T_map_odom = truth[q.frame] * q.T_odom_sensor.inverse();
    std::vector<int> counterpart(query.size(), -1);
    for (size_t i = 0; i < query.size(); ++i) {
      counterpart[i] = centroids.nearest_within((T_map_odom * query[i].centroid.cast<double>()).cast<float>(),
                                                funnel.counterpart_radius_m);
      if (counterpart[i] >= 0) ++f.counterpart;
    }
    if (!query.empty()) {
      const Matches candidates = retrieve_candidates(query, localizer.feature_index(), lc.retrieval);
      const Matches matches = filter_matches(query, targets, candidates, lc.matcher, localizer.classifier());
      f.candidates = candidates.size();
      f.matches = matches.size();
      auto count_true = [&](const Matches& ms) {
        std::set<int> hit;
        for (const Match& m : ms)
          if (counterpart[m.query] == m.target) hit.insert(m.query);
        return hit.size();
      };
      f.retrieved = count_true(candidates);
      f.classified = count_true(matches);
    }
    out.push_back(f);
    return true;
  });
  return out;
}

void print_funnel(const std::vector<FunnelQuery>& queries, int min_inliers) {
  size_t s = 0, c = 0, r = 0, k = 0, enough = 0;
  std::printf("frame   odometer  segments counterpart retrieved classified  (candidates, matches)\n");
  for (const FunnelQuery& q : queries) {
    std::printf("%5zu %9.1f m %8zu %11zu %9zu %10zu  (%zu, %zu)\n", q.frame, q.odometer_m, q.segments, q.counterpart,
                q.retrieved, q.classified, q.candidates, q.matches);
    s += q.segments, c += q.counterpart, r += q.retrieved, k += q.classified;
    if (q.classified >= static_cast<size_t>(min_inliers)) ++enough;
  }
  std::printf(
      "total: %zu segments, %zu with a counterpart, %zu retrieved, %zu classified; %zu of %zu queries have >= %d true "
      "matches\n",
      s, c, r, k, enough, queries.size(), min_inliers);
}

}  // namespace eval
}  // namespace segmatch
