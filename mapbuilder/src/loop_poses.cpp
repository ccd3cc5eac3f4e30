#include "loop_poses.h"

#include <segmatch/cli/progress.h>
#include <segmatch/core/matching/matcher.h>
#include <segmatch/posegraph/close_loops.h>

#include <cstdio>
#include <memory>

namespace segmatch::mapbuilder {

LoopCorrectedPoses close_loops_first(const io::Sequence& seq, const std::vector<size_t>& frames,
                                     const io::PipelineConfig& pipeline,
                                     const std::optional<storage::ClassifierBlob>& classifier, bool scan_edges,
                                     const volatile std::sig_atomic_t* stop_signal) {
  LoopDetectorConfig config = io::loop_detector_config(pipeline);
  std::shared_ptr<const RandomForestMatcher> rf;
  if (config.localizer.matcher.type == MatcherType::kRandomForest && classifier) {
    rf = std::make_shared<const RandomForestMatcher>(RandomForestMatcher::load(classifier->bytes));
    config.localizer.matcher.use_shapes = rf->config().use_shapes;
  } else {
    config.localizer.matcher.type = MatcherType::kL2;
    config.localizer.matcher.use_shapes = false;
  }
  std::printf("closing loops first: a local cloud every %.1f m, recent past %.0f m, %s matcher\n",
              config.local_cloud_every_m, config.exclude_recent_distance_m, rf ? "random forest" : "L2");
  posegraph::CloseLoopsOptions o;
  o.frames = frames;
  o.should_stop = [stop_signal] { return *stop_signal != 0; };
  if (scan_edges) o.scan_edges = posegraph::ScanMatchConfig{};
  cli::Progress progress("loop", frames.size(), "scans");
  o.on_scan = [&progress](size_t done, size_t) { progress.update(done); };
  const posegraph::ClosedLoops r = posegraph::close_loops(seq, config, rf, o);
  progress.finish();

  size_t downweighted = 0;
  double max_shift_m = 0;
  for (size_t i = 0; i < r.frames.size(); ++i)
    max_shift_m =
        std::max(max_shift_m, (r.T_corrected_sensor[i].translation() - r.T_odom_sensor[i].translation()).norm());
  nlohmann::json loops = nlohmann::json::array();
  if (r.last_solve)
    for (const posegraph::LoopReport& w : r.last_solve->loops) {
      const LoopClosure& l = r.loops.at(w.index);
      downweighted += w.downweighted;
      loops.push_back({{"query_frame", l.query_frame}, {"match_frame", l.match_frame}, {"weight", w.weight}});
    }
  std::printf("loops: %zu (%zu down-weighted by the optimiser); poses moved by up to %.2f m\n", r.loops.size(),
              downweighted, max_shift_m);
  LoopCorrectedPoses out;
  out.T_map_sensor = r.T_corrected_sensor;
  out.summary = {{"loops", loops}, {"downweighted", downweighted}, {"max_correction_m", max_shift_m}};
  if (scan_edges) {
    size_t accepted = 0;
    for (const auto& step : r.scan_steps) accepted += step.has_value();
    out.summary["scan_edges"] = {{"tried", r.scan_edges_tried}, {"accepted", accepted}};
    std::printf("scan edges: %zu of %zu registrations accepted\n", accepted, r.scan_edges_tried);
  }
  return out;
}

}  // namespace segmatch::mapbuilder
