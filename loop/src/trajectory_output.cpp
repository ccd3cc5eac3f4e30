#include "trajectory_output.h"

#include <segmatch/io/pose_io.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <stdexcept>

namespace segmatch::loop {
namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

nlohmann::json error_json(const posegraph::TrajectoryError& e) {
  return {{"rmse_m", e.rmse_m},
          {"rmse_horizontal_m", e.rmse_horizontal_m},
          {"rmse_vertical_m", e.rmse_vertical_m},
          {"max_m", e.max_m},
          {"final_m", e.final_m},
          {"max_at_node", e.max_index}};
}

bool downweighted(const TrajectorySummary& s, size_t loop) {
  return loop < s.loop_weights.size() && s.loop_weights[loop].downweighted;
}

// Below the map: position error against the reference along the route, odometry (grey) and
// corrected (blue), with the loops' query frames marked. ref is already aligned.
void draw_error_strip(cv::Mat& img, int top, const posegraph::ClosedLoops& r, const Poses& ref) {
  const int left = 60, right = 20, height = img.rows - top - 40;
  std::vector<double> odom, corrected;
  double peak = 0.05;
  for (size_t i = 0; i < ref.size(); ++i) {
    odom.push_back((r.T_odom_sensor[i].translation() - ref[i].translation()).norm());
    corrected.push_back((r.T_corrected_sensor[i].translation() - ref[i].translation()).norm());
    peak = std::max({peak, odom.back(), corrected.back()});
  }
  const double n = static_cast<double>(std::max<size_t>(ref.size() - 1, 1));
  auto px = [&](size_t i, double e) {
    return cv::Point(left + static_cast<int>(i / n * (img.cols - left - right)),
                     top + height - static_cast<int>(e / peak * height));
  };
  const cv::Scalar black(0, 0, 0), grey(160, 160, 160), blue(200, 100, 30);
  cv::line(img, px(0, 0), px(ref.size() - 1, 0), black, 1);
  cv::line(img, px(0, 0), px(0, peak), black, 1);
  for (const LoopClosure& l : r.loops)
    cv::line(img, px(r.node_of(l.query_frame), 0), px(r.node_of(l.query_frame), peak), cv::Scalar(0, 200, 255), 1);
  for (size_t i = 1; i < ref.size(); ++i) {
    cv::line(img, px(i - 1, odom[i - 1]), px(i, odom[i]), grey, 2, cv::LINE_AA);
    cv::line(img, px(i - 1, corrected[i - 1]), px(i, corrected[i]), blue, 2, cv::LINE_AA);
  }
  cv::putText(img, cv::format("%.2f m", peak), cv::Point(5, top + 12), cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1,
              cv::LINE_AA);
  cv::putText(img, "position error along the route: odometry (grey), corrected (blue), loops (orange)",
              cv::Point(left, top + height + 25), cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1, cv::LINE_AA);
}

// Median error of measured steps against the reference's steps, over the nodes given.
TrajectorySummary::StepError step_error(const std::vector<size_t>& nodes, const std::function<Pose3d(size_t)>& measured,
                                        const Poses& reference) {
  std::vector<double> m, deg, scale;
  for (size_t n : nodes) {
    const Pose3d truth = reference[n - 1].inverse() * reference[n];
    const Pose3d delta = truth.inverse() * measured(n);
    m.push_back(delta.translation().norm());
    deg.push_back(Eigen::AngleAxisd(delta.linear()).angle() * 180.0 / M_PI);
    if (truth.translation().norm() > 0.1)
      scale.push_back(100.0 * (measured(n).translation().norm() / truth.translation().norm() - 1.0));
  }
  return {median(m), median(deg), median(scale)};
}

void add_scan_figures(const posegraph::ClosedLoops& r, const Poses& reference, TrajectorySummary& s) {
  s.scan_edges_tried = r.scan_edges_tried;
  std::vector<size_t> nodes;
  for (size_t n = 1; n < r.scan_steps.size(); ++n)
    if (r.scan_steps[n]) nodes.push_back(n);
  s.scan_edges_accepted = nodes.size();
  if (r.last_solve) s.scan_edges_downweighted = r.last_solve->scans_downweighted;
  if (reference.empty() || nodes.empty()) return;
  s.scan_step_error = step_error(
      nodes, [&](size_t n) { return *r.scan_steps[n]; }, reference);
  s.odometry_step_error = step_error(
      nodes, [&](size_t n) { return Pose3d(r.T_odom_sensor[n - 1].inverse() * r.T_odom_sensor[n]); }, reference);
}

}  // namespace

TrajectorySummary summarize(const posegraph::ClosedLoops& r, const Poses& reference) {
  TrajectorySummary s;
  if (!reference.empty()) {
    s.odometry = posegraph::trajectory_error(r.T_odom_sensor, reference);
    s.corrected = posegraph::trajectory_error(r.T_corrected_sensor, reference);
  }
  if (r.last_solve) s.loop_weights = r.last_solve->loops;
  s.solves = r.solve_ms.size();
  s.median_solve_ms = median(r.solve_ms);
  s.max_solve_ms = r.solve_ms.empty() ? 0.0 : *std::max_element(r.solve_ms.begin(), r.solve_ms.end());
  s.map_segments_odometry = r.map_odom.size();
  s.map_segments_corrected = r.map_corrected.segments.size();
  s.merged_duplicates = r.map_corrected.merged;
  add_scan_figures(r, reference, s);
  return s;
}

nlohmann::json to_json(const TrajectorySummary& s, const std::vector<LoopClosure>& loops) {
  nlohmann::json j;
  j["alignment"] = "first pose, no scale";
  if (s.odometry) j["odometry_error"] = error_json(*s.odometry);
  if (s.corrected) j["corrected_error"] = error_json(*s.corrected);
  j["optimisations"] = s.solves;
  j["solve_ms"] = {{"median", s.median_solve_ms}, {"max", s.max_solve_ms}};
  j["downweighted_loops"] = nlohmann::json::array();
  j["loop_weights"] = nlohmann::json::array();
  for (const posegraph::LoopReport& w : s.loop_weights) {
    const LoopClosure& l = loops.at(w.index);
    const nlohmann::json one = {{"query_frame", l.query_frame},
                                {"match_frame", l.match_frame},
                                {"weight", w.weight},
                                {"residual_m", w.residual_m},
                                {"residual_deg", w.residual_deg}};
    j["loop_weights"].push_back(one);
    if (w.downweighted) j["downweighted_loops"].push_back(one);
  }
  if (s.scan_edges_tried > 0) {
    nlohmann::json scans = {{"tried", s.scan_edges_tried},
                            {"accepted", s.scan_edges_accepted},
                            {"downweighted", s.scan_edges_downweighted}};
    const auto step_json = [](const TrajectorySummary::StepError& e) {
      return nlohmann::json{
          {"median_m", e.median_m}, {"median_deg", e.median_deg}, {"median_scale_pct", e.median_scale_pct}};
    };
    if (s.scan_step_error) scans["step_error"] = step_json(*s.scan_step_error);
    if (s.odometry_step_error) scans["odometry_step_error"] = step_json(*s.odometry_step_error);
    j["scan_edges"] = scans;
  }
  j["map"] = {{"segments_odometry", s.map_segments_odometry},
              {"segments_corrected", s.map_segments_corrected},
              {"duplicates_merged", s.merged_duplicates}};
  return j;
}

void print_summary(const TrajectorySummary& s, const std::vector<LoopClosure>& loops) {
  if (s.odometry && s.corrected)
    std::printf(
        "trajectory error (first pose aligned): odometry RMSE %.3f m (xy %.3f, z %.3f), max %.3f m -> "
        "corrected RMSE %.3f m (xy %.3f, z %.3f), max %.3f m\n",
        s.odometry->rmse_m, s.odometry->rmse_horizontal_m, s.odometry->rmse_vertical_m, s.odometry->max_m,
        s.corrected->rmse_m, s.corrected->rmse_horizontal_m, s.corrected->rmse_vertical_m, s.corrected->max_m);
  std::printf("pose graph: %zu optimisations, %.0f ms median, %.0f ms max", s.solves, s.median_solve_ms,
              s.max_solve_ms);
  size_t down = 0;
  for (const posegraph::LoopReport& w : s.loop_weights) down += w.downweighted;
  std::printf("; %zu of %zu loops down-weighted\n", down, s.loop_weights.size());
  for (const posegraph::LoopReport& w : s.loop_weights)
    if (w.downweighted)
      std::printf("  down-weighted: loop %zu -> %zu, weight %.3f, disagrees by %.2f m / %.2f deg\n",
                  loops.at(w.index).query_frame, loops.at(w.index).match_frame, w.weight, w.residual_m, w.residual_deg);
  if (s.scan_edges_tried > 0) {
    std::printf("scan edges: %zu of %zu registrations accepted, %zu down-weighted", s.scan_edges_accepted,
                s.scan_edges_tried, s.scan_edges_downweighted);
    if (s.scan_step_error && s.odometry_step_error)
      std::printf(
          "; step error against the reference, median: scans %.1f cm / %.3f deg / scale %+.2f %%, odometry "
          "%.1f cm / %.3f deg / scale %+.2f %%",
          100 * s.scan_step_error->median_m, s.scan_step_error->median_deg, s.scan_step_error->median_scale_pct,
          100 * s.odometry_step_error->median_m, s.odometry_step_error->median_deg,
          s.odometry_step_error->median_scale_pct);
    std::printf("\n");
    if (s.scan_edges_downweighted * 5 > s.scan_edges_accepted)
      std::printf(
          "warning: the optimiser down-weighted %zu of %zu scan edges: the registrations disagree with the "
          "odometry far beyond their sigma. An odometry this consistent (LiDAR-inertial) is better without "
          "--scan-edges (docs/loop-closure.md)\n",
          s.scan_edges_downweighted, s.scan_edges_accepted);
  }
  std::printf(
      "segment map: %zu segments in the odometry frame, %zu on the corrected trajectory (%zu duplicates merged)\n",
      s.map_segments_odometry, s.map_segments_corrected, s.merged_duplicates);
}

void write_tum(const std::string& path, const std::vector<double>& times, const Poses& poses) {
  io::StampedPoses stamped;
  stamped.times = times;
  stamped.poses = poses;
  io::write_tum(path, stamped);
}

void write_trajectory_png(const std::string& path, const posegraph::ClosedLoops& r, const Poses& reference,
                          const TrajectorySummary& s) {
  if (r.frames.empty()) throw std::runtime_error("no poses to draw in " + path);
  Poses ref = reference;
  if (!ref.empty()) {
    const Pose3d T_align = r.T_odom_sensor.front() * ref.front().inverse();  // reference into the odometry frame
    for (Pose3d& T : ref) T = T_align * T;
  }
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (const Poses* set : std::initializer_list<const Poses*>{&r.T_odom_sensor, &r.T_corrected_sensor, &ref})
    for (const Pose3d& T : *set)
      lo = lo.cwiseMin(T.translation().head<2>()), hi = hi.cwiseMax(T.translation().head<2>());
  const int size_px = 1000, margin_px = 40;
  const double extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1.0});
  const double scale = (size_px - 2 * margin_px) / extent;
  auto px = [&](const Pose3d& T) {
    return cv::Point(margin_px + static_cast<int>((T.translation().x() - lo.x()) * scale),
                     size_px - margin_px - static_cast<int>((T.translation().y() - lo.y()) * scale));
  };
  const int strip_px = ref.empty() ? 0 : 260;
  cv::Mat img(size_px + strip_px, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  auto polyline = [&](const Poses& P, const cv::Scalar& colour, int width) {
    for (size_t i = 0; i + 1 < P.size(); ++i) cv::line(img, px(P[i]), px(P[i + 1]), colour, width, cv::LINE_AA);
  };
  polyline(r.T_odom_sensor, cv::Scalar(160, 160, 160), 2);
  polyline(ref, cv::Scalar(60, 180, 60), 4);
  polyline(r.T_corrected_sensor, cv::Scalar(200, 100, 30), 2);
  for (size_t k = 0; k < r.loops.size(); ++k) {
    const Pose3d& a = r.T_corrected_sensor[r.node_of(r.loops[k].query_frame)];
    const Pose3d& b = r.T_corrected_sensor[r.node_of(r.loops[k].match_frame)];
    const bool down = downweighted(s, k);
    cv::circle(img, px(a), down ? 7 : 5, down ? cv::Scalar(40, 40, 220) : cv::Scalar(0, 140, 255), 2, cv::LINE_AA);
    cv::line(img, px(a), px(b), down ? cv::Scalar(40, 40, 220) : cv::Scalar(0, 140, 255), 2, cv::LINE_AA);
  }
  std::string legend = "odometry (grey), corrected (blue)";
  if (!ref.empty()) legend += ", reference (green)";
  legend += ", loops (orange; red: down-weighted); " + std::to_string(static_cast<int>(extent)) + " m across";
  cv::putText(img, legend, cv::Point(10, 22), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  if (s.odometry && s.corrected)
    cv::putText(
        img,
        cv::format("error (first pose aligned): odometry RMSE %.2f m, max %.2f m; corrected RMSE %.2f m, max %.2f m",
                   s.odometry->rmse_m, s.odometry->max_m, s.corrected->rmse_m, s.corrected->max_m),
        cv::Point(10, 44), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  if (!ref.empty()) draw_error_strip(img, size_px, r, ref);
  if (!cv::imwrite(path, img)) throw std::runtime_error("cannot write " + path);
}

}  // namespace segmatch::loop
