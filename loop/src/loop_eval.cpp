#include "loop_eval.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace segmatch::loop {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

LoopScore score(const LoopClosure& loop, const Poses& truth, const EvalConfig& c) {
  const Pose3d T_true = truth[loop.query_frame].inverse() * truth[loop.match_frame];
  const Pose3d E = loop.T_query_match.inverse() * T_true;
  LoopScore s;
  s.translation_error_m = E.translation().norm();
  s.rotation_error_deg = Eigen::AngleAxisd(E.linear()).angle() * kDegPerRad;
  s.correct = s.translation_error_m <= c.max_translation_error_m && s.rotation_error_deg <= c.max_rotation_error_deg;
  return s;
}

// Distance along the true path at every frame from first_frame on (0 before).
std::vector<double> path_length(const Poses& truth, size_t first_frame, size_t last_frame) {
  std::vector<double> odo(last_frame + 1, 0.0);
  for (size_t i = first_frame + 1; i <= last_frame; ++i)
    odo[i] = odo[i - 1] + (truth[i].translation() - truth[i - 1].translation()).norm();
  return odo;
}

bool is_revisit(size_t q, const Poses& truth, const std::vector<double>& odo, size_t first_frame, const EvalConfig& c) {
  for (size_t m = first_frame; m < q && odo[q] - odo[m] > c.min_revisit_gap_m; ++m)
    if ((truth[q].translation() - truth[m].translation()).norm() <= c.revisit_radius_m) return true;
  return false;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void summarise_errors(Evaluation& e) {
  std::vector<double> t, r;
  for (const LoopScore& s : e.scores)
    if (s.correct) t.push_back(s.translation_error_m), r.push_back(s.rotation_error_deg);
  e.median_translation_error_m = median(t);
  e.median_rotation_error_deg = median(r);
  e.max_translation_error_m = t.empty() ? 0.0 : *std::max_element(t.begin(), t.end());
  e.max_rotation_error_deg = r.empty() ? 0.0 : *std::max_element(r.begin(), r.end());
}

// Precision and recall at each translation threshold: loops within it (and the rotation
// threshold), revisit local clouds with such a loop.
std::vector<ThresholdPoint> threshold_curve(const std::vector<LoopClosure>& loops, const std::vector<LoopScore>& scores,
                                            const std::vector<size_t>& revisit_frames, const EvalConfig& c) {
  std::vector<ThresholdPoint> curve;
  for (double t : c.curve_translation_m) {
    ThresholdPoint p;
    p.translation_m = t;
    std::vector<size_t> good_frames;
    for (size_t i = 0; i < loops.size(); ++i) {
      if (scores[i].translation_error_m > t || scores[i].rotation_error_deg > c.max_rotation_error_deg) continue;
      ++p.true_loops;
      good_frames.push_back(loops[i].query_frame);
    }
    for (size_t f : revisit_frames)
      p.detected_revisit_clouds += std::find(good_frames.begin(), good_frames.end(), f) != good_frames.end();
    p.precision = loops.empty() ? 1.0 : static_cast<double>(p.true_loops) / loops.size();
    p.recall = revisit_frames.empty() ? 0.0 : static_cast<double>(p.detected_revisit_clouds) / revisit_frames.size();
    curve.push_back(p);
  }
  return curve;
}

}  // namespace

Evaluation evaluate(const std::vector<LoopClosure>& loops, const std::vector<size_t>& processed, const Poses& truth,
                    size_t first_frame, const EvalConfig& c) {
  Evaluation e;
  size_t last = first_frame;
  for (size_t f : processed) last = std::max(last, f);
  for (const LoopClosure& l : loops) last = std::max({last, l.query_frame, l.match_frame});
  if (last >= truth.size())
    throw std::invalid_argument("the ground truth has " + std::to_string(truth.size()) + " poses, frame " +
                                std::to_string(last) + " needs one");
  for (const LoopClosure& l : loops) {
    e.scores.push_back(score(l, truth, c));
    (e.scores.back().correct ? e.true_loops : e.false_loops)++;
  }
  std::vector<bool> true_at(last + 1, false);
  for (size_t i = 0; i < loops.size(); ++i)
    if (e.scores[i].correct) true_at[loops[i].query_frame] = true;
  const std::vector<double> odo = path_length(truth, first_frame, last);
  e.processed_clouds = processed.size();
  bool in_stretch = false;
  std::vector<size_t> revisit_frames;
  for (size_t f : processed) {
    const bool revisit = is_revisit(f, truth, odo, first_frame, c);
    if (!revisit) {
      in_stretch = false;
      continue;
    }
    ++e.revisit_clouds;
    revisit_frames.push_back(f);
    if (!in_stretch) e.stretches.push_back(RevisitStretch{f, f});
    in_stretch = true;
    RevisitStretch& s = e.stretches.back();
    s.last_frame = f;
    s.length_m = odo[f] - odo[s.first_frame];
    ++s.clouds;
    if (!true_at[f]) continue;
    ++e.detected_revisit_clouds;
    ++s.detected_clouds;
    if (!s.detected) s.driven_before_detection_m = odo[f] - odo[s.first_frame];
    s.detected = true;
  }
  e.precision = loops.empty() ? 1.0 : static_cast<double>(e.true_loops) / loops.size();
  e.recall = e.revisit_clouds ? static_cast<double>(e.detected_revisit_clouds) / e.revisit_clouds : 0.0;
  summarise_errors(e);
  e.curve = threshold_curve(loops, e.scores, revisit_frames, c);
  return e;
}

std::string to_json(const Evaluation& e, const EvalConfig& c) {
  nlohmann::json j;
  j["criteria"] = {{"max_translation_error_m", c.max_translation_error_m},
                   {"max_rotation_error_deg", c.max_rotation_error_deg},
                   {"revisit_radius_m", c.revisit_radius_m},
                   {"min_revisit_gap_m", c.min_revisit_gap_m}};
  j["loops"] = e.scores.size();
  j["true_loops"] = e.true_loops;
  j["false_loops"] = e.false_loops;
  j["precision"] = e.precision;
  j["processed_local_clouds"] = e.processed_clouds;
  j["revisit_local_clouds"] = e.revisit_clouds;
  j["detected_revisit_local_clouds"] = e.detected_revisit_clouds;
  j["recall"] = e.recall;
  j["true_loop_translation_error_m"] = {{"median", e.median_translation_error_m}, {"max", e.max_translation_error_m}};
  j["true_loop_rotation_error_deg"] = {{"median", e.median_rotation_error_deg}, {"max", e.max_rotation_error_deg}};
  j["curve"] = nlohmann::json::array();
  for (const ThresholdPoint& p : e.curve)
    j["curve"].push_back({{"max_translation_error_m", p.translation_m},
                          {"true_loops", p.true_loops},
                          {"precision", p.precision},
                          {"detected_revisit_local_clouds", p.detected_revisit_clouds},
                          {"recall", p.recall}});
  j["per_loop"] = nlohmann::json::array();
  for (const LoopScore& s : e.scores)
    j["per_loop"].push_back({{"translation_error_m", s.translation_error_m},
                             {"rotation_error_deg", s.rotation_error_deg},
                             {"correct", s.correct}});
  j["revisits"] = nlohmann::json::array();
  for (const RevisitStretch& s : e.stretches) {
    nlohmann::json r = {{"first_frame", s.first_frame},
                        {"last_frame", s.last_frame},
                        {"length_m", s.length_m},
                        {"local_clouds", s.clouds},
                        {"detected_local_clouds", s.detected_clouds},
                        {"detected", s.detected}};
    r["driven_before_first_detection_m"] = s.detected ? nlohmann::json(s.driven_before_detection_m) : nlohmann::json();
    j["revisits"].push_back(r);
  }
  return j.dump(2) + "\n";
}

void print_summary(const Evaluation& e, const EvalConfig& c) {
  std::printf("loops: %zu true, %zu false (within %.1f m / %.1f deg); precision %.3f\n", e.true_loops, e.false_loops,
              c.max_translation_error_m, c.max_rotation_error_deg, e.precision);
  std::printf("revisit local clouds: %zu of %zu processed, %zu with a true loop; recall %.3f\n", e.revisit_clouds,
              e.processed_clouds, e.detected_revisit_clouds, e.recall);
  if (e.true_loops)
    std::printf("true loop error: median %.3f m / %.2f deg, max %.3f m / %.2f deg\n", e.median_translation_error_m,
                e.median_rotation_error_deg, e.max_translation_error_m, e.max_rotation_error_deg);
  if (!e.curve.empty()) {
    std::printf("precision / recall by translation threshold (rotation <= %.1f deg):", c.max_rotation_error_deg);
    for (const ThresholdPoint& p : e.curve) std::printf(" %.2g m %.2f/%.2f", p.translation_m, p.precision, p.recall);
    std::printf("\n");
  }
  for (const RevisitStretch& s : e.stretches) {
    if (s.detected)
      std::printf("revisit frames %zu..%zu (%.0f m, %zu clouds): first detected after %.1f m, %zu clouds detected\n",
                  s.first_frame, s.last_frame, s.length_m, s.clouds, s.driven_before_detection_m, s.detected_clouds);
    else
      std::printf("revisit frames %zu..%zu (%.0f m, %zu clouds): never detected\n", s.first_frame, s.last_frame,
                  s.length_m, s.clouds);
  }
}

}  // namespace segmatch::loop
