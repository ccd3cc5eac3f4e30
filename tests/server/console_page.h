// The operator's page as a browser shows it, for console_page_test.cpp: a headless Chromium run
// (the DOM after the page's scripts ran, and its pixels), the view transform the page published,
// what it draws of /api/answers, and checks of the pixels against what the API served.
#pragma once

#include "support/run_command.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace segmatch::testing {

inline std::string chromium_binary() {
  for (const char* name : {"chromium", "chromium-browser"}) {
    const test::CommandResult r = test::run_command(std::string("command -v ") + name);
    if (r.code == 0 && !r.output.empty()) return r.output.substr(0, r.output.find('\n'));
  }
  return "";
}

struct PageRun {
  std::string dom;  // the DOM after the page's scripts ran
  cv::Mat shot;     // its screenshot, 1200 x 800
};

// One headless Chromium run on `url` taking both the DOM and the screenshot (`png`);
// --virtual-time-budget lets the page load, fetch and poll (virtual time stands still while a
// fetch is pending) first. Each run has its own profile. Without
// --run-all-compositor-stages-before-draw a --screenshot run hung 6 times in 10 here (virtual
// time waiting on a frame that is never drawn); with it, 0 in 20. A run not finished in 25 s
// (they take 3-10 s) is still killed and tried again, up to three times.
inline PageRun open_page(const std::string& binary, const std::string& url, const std::string& folder,
                         const std::string& png) {
  static int runs = 0;
  test::CommandResult r;
  std::string cmd;
  for (int attempt = 0; attempt < 3; ++attempt) {
    cmd = "timeout -k 5 25 " + binary +
          " --headless --disable-gpu --no-sandbox --hide-scrollbars --no-first-run "
          "--disable-extensions --force-device-scale-factor=1 --window-size=1200,800 --virtual-time-budget=4000 "
          "--run-all-compositor-stages-before-draw --user-data-dir=" +
          folder + "/profile-" + std::to_string(++runs) + " --dump-dom --screenshot=" + png + " '" + url + "'";
    r = test::run_command("(" + cmd + " > " + folder + "/chromium.out 2> " + folder + "/chromium.err)");
    if (r.code == 0) break;
  }
  EXPECT_EQ(r.code, 0) << cmd << "\n" << r.output;
  std::ifstream in(folder + "/chromium.out");
  std::stringstream s;
  s << in.rdbuf();
  return {s.str(), cv::imread(png, cv::IMREAD_COLOR)};
}

inline std::string attribute(const std::string& dom, const std::string& element_id, const std::string& name) {
  const size_t at = dom.find("id=\"" + element_id + "\"");
  if (at == std::string::npos) return "";
  const size_t open = dom.rfind('<', at), close = dom.find('>', at);
  const std::string tag = dom.substr(open, close - open);
  std::smatch m;
  if (!std::regex_search(tag, m, std::regex(name + "=\"([^\"]*)\""))) return "";
  return m[1];
}

inline std::string element_text(const std::string& dom, const std::string& element_id) {
  const size_t at = dom.find("id=\"" + element_id + "\"");
  if (at == std::string::npos) return "";
  const size_t start = dom.find('>', at) + 1;
  return dom.substr(start, dom.find('<', start) - start);
}

inline std::string html_escaped(const std::string& text) {
  std::string out;
  for (char c : text) out += c == '&' ? "&amp;" : c == '<' ? "&lt;" : c == '>' ? "&gt;" : std::string(1, c);
  return out;
}

// The transform the page published on its canvas (docs/console.md): the canvas is ?size=WxH at
// the page's top left; the panel covers it from x = 840 (1200 - 360) on.
struct View {
  double cx = 0, cy = 0, scale = 0, width = 0, height = 0;
  cv::Point2d px(double x, double y) const { return {width / 2 + (x - cx) * scale, height / 2 - (y - cy) * scale}; }
  bool shown(const cv::Point2d& p, double margin = 0) const {
    return p.x >= margin && p.y >= margin && p.x < std::min(width, 840.0) - margin && p.y < height - margin;
  }
};

inline View view_of(const std::string& dom, double width, double height) {
  const std::string scale = attribute(dom, "map", "data-scale");
  EXPECT_FALSE(scale.empty()) << dom.substr(0, 4000);
  if (scale.empty()) return {};
  return {std::stod(attribute(dom, "map", "data-cx")), std::stod(attribute(dom, "map", "data-cy")), std::stod(scale),
          width, height};
}

// Pixels within `radius` of (x, y) whose colour passes `is`.
template <typename Pred>
int pixels_near(const cv::Mat& image, double x, double y, int radius, Pred is) {
  int n = 0;
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx) {
      const int px = static_cast<int>(std::lround(x)) + dx, py = static_cast<int>(std::lround(y)) + dy;
      if (px < 0 || py < 0 || px >= image.cols || py >= image.rows) continue;
      const cv::Vec3b bgr = image.at<cv::Vec3b>(py, px);
      n += is(bgr[2], bgr[1], bgr[0]);
    }
  return n;
}

// The page's colours (server/console/app.js kColors, style.css), with room for antialiasing
// and fading. The trajectory is grey #8b949e at 80 % over the background #0d1117.
inline bool segment_blue(int r, int g, int b) { return b > 200 && r < 110 && g > 90 && g < 170; }
inline bool localized_green(int r, int g, int b) { return g > 170 && r < 90 && b < 160; }
inline bool refused_red(int r, int g, int b) { return r > 190 && g < 90 && b < 120; }
inline bool trajectory_grey(int r, int g, int b) {
  return r > 60 && r < 200 && std::abs(r - g) < 20 && std::abs(g - b) < 20;
}
inline bool panel_background(int r, int g, int b) {  // style.css #panel: #161b22
  return std::abs(r - 0x16) < 6 && std::abs(g - 0x1b) < 6 && std::abs(b - 0x22) < 6;
}

// One answer as the page draws it: each client's (peer's) last 20, the clients in the order
// they were last heard from, the newest of each with its heading and covariance ellipse.
struct DrawnAnswer {
  nlohmann::json answer;
  bool newest = false;
  double x() const { return answer["pose"]["x"].get<double>(); }
  double y() const { return answer["pose"]["y"].get<double>(); }
  bool localized() const { return answer["status"] == "localized"; }
};

inline std::vector<DrawnAnswer> drawn_answers(const nlohmann::json& answers) {
  std::vector<std::pair<std::string, std::vector<nlohmann::json>>> clients;  // last heard last
  for (const nlohmann::json& a : answers) {
    const std::string peer = a["peer"];
    auto it = std::find_if(clients.begin(), clients.end(), [&](const auto& c) { return c.first == peer; });
    std::pair<std::string, std::vector<nlohmann::json>> client{peer, {}};
    if (it != clients.end()) client = std::move(*it), clients.erase(it);
    client.second.push_back(a);
    if (client.second.size() > 20) client.second.erase(client.second.begin());
    clients.push_back(std::move(client));
  }
  std::vector<DrawnAnswer> out;
  for (const auto& [peer, list] : clients)
    for (size_t i = 0; i < list.size(); ++i)
      if (list[i].contains("pose")) out.push_back({list[i], i + 1 == list.size()});
  return out;
}

// The segments blue at (nearly) every centroid shown and nowhere in the margin; pixels under
// an answer's mark or the "live" badge (top right) are not checked.
inline void check_segments(const cv::Mat& shot, const View& v, const std::vector<Eigen::Vector3d>& centroids,
                           const std::vector<DrawnAnswer>& drawn) {
  size_t blue = 0, checked = 0;
  for (const Eigen::Vector3d& c : centroids) {
    const cv::Point2d p = v.px(c.x(), c.y());
    bool hidden = !v.shown(p, 2) || (p.x > 780 && p.y < 30);
    for (const DrawnAnswer& a : drawn) hidden |= cv::norm(p - v.px(a.x(), a.y())) < 22;
    if (hidden) continue;
    ++checked;
    blue += pixels_near(shot, p.x, p.y, 1, segment_blue) > 0;
  }
  std::printf("[console] %zu of %zu segment centroids blue\n", blue, checked);
  EXPECT_GT(checked, 50u);
  EXPECT_GE(blue, checked * 95 / 100) << blue << " of " << checked << " segment centroids drawn blue";
  EXPECT_EQ(pixels_near(shot, 6, 6, 5, segment_blue), 0);
}

// A green disc at every localized answer drawn, unless a later mark of another colour lies on it.
inline void check_localized(const cv::Mat& shot, const View& v, const std::vector<DrawnAnswer>& drawn) {
  size_t checked = 0;
  for (size_t i = 0; i < drawn.size(); ++i) {
    const cv::Point2d p = v.px(drawn[i].x(), drawn[i].y());
    bool covered = !drawn[i].localized() || !v.shown(p, 3);
    for (size_t j = i + 1; j < drawn.size() && !covered; ++j)
      covered = !drawn[j].localized() && cv::norm(p - v.px(drawn[j].x(), drawn[j].y())) < 10;
    if (covered) continue;
    ++checked;
    // The newest is a 7 px disc, the older ones 3 px: either fills most of the 5 x 5 around it.
    EXPECT_GE(pixels_near(shot, p.x, p.y, 2, localized_green), 12) << "no localized answer drawn at " << p;
  }
  EXPECT_GE(checked, 1u);
}

// A red ring, not a disc, at a refusal's prior.
inline void check_refusal(const cv::Mat& shot, const View& v, const Eigen::Vector3d& prior) {
  const cv::Point2d r = v.px(prior.x(), prior.y());
  EXPECT_GE(pixels_near(shot, r.x, r.y, 9, refused_red), 15) << "no refusal drawn at " << r;
  EXPECT_LE(pixels_near(shot, r.x, r.y, 2, refused_red), 4) << "a refusal is a ring, not a disc";
}

// The first traversal (/api/map's trajectory) grey along its whole length: sampled every 5 px,
// except where a segment (drawn over it), an answer's mark or the badge may hide it.
inline void check_trajectory(const cv::Mat& shot, const View& v, const nlohmann::json& trajectory,
                             const std::vector<Eigen::Vector3d>& centroids, const std::vector<DrawnAnswer>& drawn) {
  cv::Mat1b hidden(shot.rows, shot.cols, uchar{0});
  for (const Eigen::Vector3d& c : centroids) cv::circle(hidden, v.px(c.x(), c.y()), 7, 255, cv::FILLED);
  for (const DrawnAnswer& a : drawn) cv::circle(hidden, v.px(a.x(), a.y()), 24, 255, cv::FILLED);
  cv::rectangle(hidden, cv::Rect(780, 0, 60, 30), 255, cv::FILLED);
  size_t grey = 0, checked = 0;
  double to_next = 0;  // px along the line to the next sample
  for (size_t i = 1; i < trajectory.size(); ++i) {
    const cv::Point2d a = v.px(trajectory[i - 1][0], trajectory[i - 1][1]),
                      b = v.px(trajectory[i][0], trajectory[i][1]);
    const double length = cv::norm(b - a);
    for (; to_next <= length; to_next += 5) {
      const cv::Point2d p = a + (b - a) * (to_next / std::max(length, 1e-9));
      if (!v.shown(p, 2) || hidden(static_cast<int>(p.y), static_cast<int>(p.x))) continue;
      ++checked;
      grey += pixels_near(shot, p.x, p.y, 1, trajectory_grey) > 0;
    }
    to_next -= length;
  }
  std::printf("[console] %zu of %zu points along the trajectory grey\n", grey, checked);
  EXPECT_GT(checked, 30u) << "too little of the trajectory in view to check";
  EXPECT_GE(grey, checked * 90 / 100) << grey << " of " << checked << " points along the trajectory drawn grey";
  EXPECT_EQ(pixels_near(shot, 6, 6, 5, trajectory_grey), 0);
}

// The 2-sigma ellipse of the answer's horizontal covariance [xx, xy, yy] (m^2), a green ring:
// green on (nearly) every point of the ellipse, hardly any at 0.6 and 1.5 times its size. Its
// axes are worked out here independently of the page's closed form. Points within 20 px of the
// pose (the disc and the heading) are not checked.
inline void check_ellipse(const cv::Mat& shot, const View& v, const DrawnAnswer& answer) {
  const nlohmann::json& c = answer.answer["covariance_xy"];
  Eigen::Matrix2d cov;
  cov << c[0].get<double>(), c[1].get<double>(), c[1].get<double>(), c[2].get<double>();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
  const Eigen::Vector2d minor = eig.eigenvectors().col(0) * 2 * std::sqrt(std::max(0.0, eig.eigenvalues()(0)));
  const Eigen::Vector2d major = eig.eigenvectors().col(1) * 2 * std::sqrt(eig.eigenvalues()(1));
  const cv::Point2d centre = v.px(answer.x(), answer.y());
  size_t on = 0, on_checked = 0, off = 0, off_checked = 0;
  for (int k = 0; k < 90; ++k) {
    const double t = k * 2 * M_PI / 90;
    const Eigen::Vector2d d = major * std::cos(t) + minor * std::sin(t);
    for (const double f : {1.0, 0.6, 1.5}) {
      const cv::Point2d p = v.px(answer.x() + f * d.x(), answer.y() + f * d.y());
      if (!v.shown(p, 3) || cv::norm(p - centre) < 20) continue;
      const bool green = pixels_near(shot, p.x, p.y, f == 1.0 ? 2 : 1, localized_green) > 0;
      if (f == 1.0)
        ++on_checked, on += green;
      else
        ++off_checked, off += green;
    }
  }
  std::printf(
      "[console] ellipse (semi-axes %.0f and %.0f px): %zu of %zu points on it green, %zu of %zu inside and outside\n",
      major.norm() * v.scale, minor.norm() * v.scale, on, on_checked, off, off_checked);
  EXPECT_GE(on_checked, 30u) << "the ellipse is too small or out of view to check";
  EXPECT_GE(on, on_checked * 90 / 100) << on << " of " << on_checked << " points of the ellipse drawn green";
  EXPECT_LE(off, off_checked / 10) << off << " of " << off_checked << " points inside and outside the ellipse green";
}

}  // namespace segmatch::testing
