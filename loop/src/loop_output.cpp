#include "loop_output.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <unordered_map>

namespace segmatch::loop {
namespace {

std::ofstream open_out(const std::string& path) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write " + path);
  out.precision(9);
  return out;
}

void close_out(std::ofstream& out, const std::string& path) {
  out.flush();
  if (!out) throw std::runtime_error("failed writing " + path);
}

// x y z qx qy qz qw
void put_pose(std::ostream& out, const Pose3d& T) {
  const Eigen::Quaterniond q(T.linear());
  const Eigen::Vector3d t = T.translation();
  out << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w();
}

// Upper triangle of the information matrix, row by row (21 values).
void put_information(std::ostream& out, const posegraph::Matrix6d& sqrt_information) {
  const posegraph::Matrix6d info = sqrt_information.transpose() * sqrt_information;
  for (int i = 0; i < 6; ++i)
    for (int j = i; j < 6; ++j) out << ' ' << info(i, j);
}

}  // namespace

void write_loops_txt(const std::string& path, const std::vector<LoopClosure>& loops) {
  std::ofstream out = open_out(path);
  out << "# query_frame match_frame x y z qx qy qz qw inliers confidence  (T_query_match)\n";
  for (const LoopClosure& l : loops) {
    out << l.query_frame << ' ' << l.match_frame << ' ';
    put_pose(out, l.T_query_match);
    out << ' ' << l.inliers << ' ' << l.confidence << '\n';
  }
  close_out(out, path);
}

void write_g2o(const std::string& path, const std::vector<size_t>& frames, const Poses& T_world_node,
               const posegraph::PoseGraph& graph) {
  std::ofstream out = open_out(path);
  for (size_t i = 0; i < frames.size(); ++i) {
    out << "VERTEX_SE3:QUAT " << frames[i] << ' ';
    put_pose(out, T_world_node[i]);
    out << '\n';
  }
  for (const auto* edges : {&graph.odometry, &graph.loops})
    for (const posegraph::Edge& e : *edges) {
      out << "EDGE_SE3:QUAT " << frames.at(e.from) << ' ' << frames.at(e.to) << ' ';
      put_pose(out, e.T_from_to);
      put_information(out, e.sqrt_information);
      out << '\n';
    }
  if (!frames.empty()) out << "FIX " << frames.front() << '\n';
  close_out(out, path);
}

void write_png(const std::string& path, const std::vector<size_t>& frames, const Poses& T_odom_sensor,
               const std::vector<size_t>& processed, const std::vector<LoopClosure>& loops,
               const std::vector<bool>& correct) {
  if (frames.empty()) throw std::runtime_error("no poses to draw in " + path);
  std::unordered_map<size_t, Eigen::Vector2d> at;
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (size_t i = 0; i < frames.size(); ++i) {
    const Eigen::Vector2d p = T_odom_sensor[i].translation().head<2>();
    at[frames[i]] = p;
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const int size_px = 1000, margin_px = 40;
  const double extent = std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1.0});
  const double scale = (size_px - 2 * margin_px) / extent;
  auto px = [&](const Eigen::Vector2d& p) {
    return cv::Point(margin_px + static_cast<int>((p.x() - lo.x()) * scale),
                     size_px - margin_px - static_cast<int>((p.y() - lo.y()) * scale));
  };
  cv::Mat img(size_px, size_px, CV_8UC3, cv::Scalar(255, 255, 255));
  for (size_t i = 0; i + 1 < frames.size(); ++i)
    cv::line(img, px(at[frames[i]]), px(at[frames[i + 1]]), cv::Scalar(150, 150, 150), 2, cv::LINE_AA);
  for (size_t f : processed)
    if (at.count(f)) cv::circle(img, px(at[f]), 3, cv::Scalar(200, 120, 40), cv::FILLED, cv::LINE_AA);
  for (size_t k = 0; k < loops.size(); ++k) {
    if (!at.count(loops[k].query_frame) || !at.count(loops[k].match_frame)) continue;
    const bool ok = correct.empty() || correct[k];
    cv::line(img, px(at[loops[k].query_frame]), px(at[loops[k].match_frame]),
             ok ? cv::Scalar(40, 170, 40) : cv::Scalar(40, 40, 220), 2, cv::LINE_AA);
  }
  const std::string legend = "odometry (grey), local clouds (blue), loops: true (green) / false (red); " +
                             std::to_string(static_cast<int>(extent)) + " m across";
  cv::putText(img, legend, cv::Point(10, 22), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  if (!cv::imwrite(path, img)) throw std::runtime_error("cannot write " + path);
}

void write_curve_png(const std::string& path, const std::vector<ThresholdPoint>& curve, double rotation_deg) {
  if (curve.empty()) throw std::runtime_error("no thresholds to draw in " + path);
  const int w = 800, h = 500, left = 70, right = 30, top = 50, bottom = 60;
  const double lx0 = std::log10(curve.front().translation_m), lx1 = std::log10(curve.back().translation_m);
  const auto px = [&](double t, double v) {
    const double fx = lx1 > lx0 ? (std::log10(t) - lx0) / (lx1 - lx0) : 0.5;
    return cv::Point(left + static_cast<int>(fx * (w - left - right)),
                     h - bottom - static_cast<int>(v * (h - top - bottom)));
  };
  cv::Mat img(h, w, CV_8UC3, cv::Scalar(255, 255, 255));
  const cv::Scalar black(0, 0, 0), grey(200, 200, 200);
  for (int k = 0; k <= 4; ++k) {  // horizontal grid at 0, 0.25, .. 1
    const double v = k / 4.0;
    cv::line(img, px(curve.front().translation_m, v), px(curve.back().translation_m, v), grey, 1);
    cv::putText(img, cv::format("%.2f", v), cv::Point(20, px(curve.front().translation_m, v).y + 5),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1, cv::LINE_AA);
  }
  for (const ThresholdPoint& p : curve) {
    const cv::Point base = px(p.translation_m, 0.0);
    cv::line(img, base, px(p.translation_m, 1.0), grey, 1);
    cv::putText(img, cv::format("%g", p.translation_m), cv::Point(base.x - 12, h - bottom + 20),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, black, 1, cv::LINE_AA);
  }
  const cv::Scalar blue(200, 90, 30), green(40, 160, 40);
  for (size_t i = 0; i < curve.size(); ++i) {
    const cv::Point pp = px(curve[i].translation_m, curve[i].precision),
                    pr = px(curve[i].translation_m, curve[i].recall);
    cv::circle(img, pp, 4, blue, cv::FILLED, cv::LINE_AA);
    cv::circle(img, pr, 4, green, cv::FILLED, cv::LINE_AA);
    if (i == 0) continue;
    cv::line(img, px(curve[i - 1].translation_m, curve[i - 1].precision), pp, blue, 2, cv::LINE_AA);
    cv::line(img, px(curve[i - 1].translation_m, curve[i - 1].recall), pr, green, 2, cv::LINE_AA);
  }
  cv::putText(
      img, cv::format("precision (blue), recall over revisit local clouds (green); rotation <= %.1f deg", rotation_deg),
      cv::Point(10, 25), cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1, cv::LINE_AA);
  cv::putText(img, "translation error threshold (m, log scale)", cv::Point(w / 2 - 160, h - 15),
              cv::FONT_HERSHEY_SIMPLEX, 0.5, black, 1, cv::LINE_AA);
  if (!cv::imwrite(path, img)) throw std::runtime_error("cannot write " + path);
}

}  // namespace segmatch::loop
