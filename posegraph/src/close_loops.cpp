#include "segmatch/posegraph/close_loops.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace segmatch::posegraph {

size_t ClosedLoops::node_of(size_t frame) const {
  const auto it = std::lower_bound(frames.begin(), frames.end(), frame);
  if (it == frames.end() || *it != frame) throw std::out_of_range("frame " + std::to_string(frame) + " was not fed");
  return static_cast<size_t>(it - frames.begin());
}

namespace {

void print_step(size_t frame, const LoopStep& step) {
  std::fprintf(stderr, "\nframe %zu: %zu segments, %zu eligible targets, %zu in map, %.0f ms%s %s\n", frame,
               step.query_segments, step.eligible_targets, step.map_segments, step.total_ms, step.loop ? " LOOP" : ":",
               step.reason.c_str());
}

void print_loop(const LoopClosure& l, const OptimizationResult* solve) {
  std::fprintf(stderr, "\nloop: frame %zu -> %zu, %zu inliers, confidence %.2f, |t| %.2f m", l.query_frame,
               l.match_frame, l.inliers, l.confidence, l.T_query_match.translation().norm());
  if (solve) std::fprintf(stderr, "; optimised in %.0f ms, weight %.2f", solve->solve_ms, solve->loops.back().weight);
  std::fprintf(stderr, "\n");
}

// Moves the detector's map with the keyframes it was seen from.
void correct_map(const LoopDetector& detector, ClosedLoops& r, const SegmentMapConfig& merge) {
  r.map_odom = detector.map_segments();
  r.map_corrected = correct_segment_map(
      r.map_odom, detector.map_segment_frames(),
      [&](size_t frame) {
        const size_t n = r.node_of(frame);
        return Pose3d(r.T_corrected_sensor[n] * r.T_odom_sensor[n].inverse());
      },
      merge);
}

void add_scan_edge(ScanMatcher& matcher, const PointCloud& scan, const Pose3d& T_odom_sensor, size_t node,
                   IncrementalPoseGraph& graph, ClosedLoops& r) {
  const std::optional<ScanStep> step = matcher.add(scan, T_odom_sensor);
  r.scan_steps.emplace_back();
  if (!step) return;
  ++r.scan_edges_tried;
  if (!step->accepted) return;
  graph.add_scan_edge(node - 1, step->T_previous_this);
  r.scan_steps.back() = step->T_previous_this;
}

}  // namespace

ClosedLoops close_loops(const io::Sequence& seq, const LoopDetectorConfig& config,
                        std::shared_ptr<const RandomForestMatcher> classifier, const CloseLoopsOptions& o) {
  for (size_t i = 0; i < o.frames.size(); ++i)
    if (o.frames[i] >= seq.size() || (i > 0 && o.frames[i] <= o.frames[i - 1]))
      throw std::invalid_argument("close_loops: frames must increase and lie within the sequence's 0.." +
                                  std::to_string(seq.size() - 1));
  LoopDetector detector(config, std::move(classifier));
  IncrementalPoseGraph graph(o.graph);
  std::optional<ScanMatcher> scans;
  if (o.scan_edges) scans.emplace(*o.scan_edges);
  ClosedLoops r;
  for (size_t frame : o.frames) {
    if (o.should_stop && o.should_stop()) break;
    const io::CloudData scan = seq.scan(frame);
    const LoopStep step = detector.process(scan.points, seq.poses()[frame], frame, seq.times()[frame]);
    r.frames.push_back(frame);
    r.T_odom_sensor.push_back(seq.poses()[frame]);
    const size_t node = graph.add_node(seq.poses()[frame]);
    if (scans) add_scan_edge(*scans, scan.points, seq.poses()[frame], node, graph, r);
    if (step.processed) {
      r.processed.push_back(frame);
      r.step_ms.push_back(step.total_ms);
      if (o.verbose) print_step(frame, step);
    }
    if (step.loop) {
      const LoopClosure& l = *step.loop;
      graph.add_loop_edge(r.node_of(l.query_frame), r.node_of(l.match_frame), l.T_query_match, l.confidence);
      if (o.optimize) {
        r.last_solve = graph.solve();
        r.solve_ms.push_back(r.last_solve->solve_ms);
      }
      print_loop(l, o.optimize ? &*r.last_solve : nullptr);
    }
    if (o.on_scan) o.on_scan(r.frames.size(), o.frames.size());
  }
  if (o.optimize && !graph.graph().scans.empty()) {  // the scan edges after the last loop count too
    r.last_solve = graph.solve();
    r.solve_ms.push_back(r.last_solve->solve_ms);
  }
  r.loops = detector.loops();
  r.graph = graph.graph();
  r.T_corrected_sensor = o.optimize ? graph.estimate() : r.T_odom_sensor;
  correct_map(detector, r, config.segment_map);
  return r;
}

}  // namespace segmatch::posegraph
