#include "segmatch/eval/plots.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace segmatch {
namespace eval {
namespace {

const cv::Scalar kWhite(255, 255, 255), kBlack(0, 0, 0), kGrey(170, 170, 170), kLightBlue(235, 190, 120),
    kGreen(60, 170, 40), kRed(40, 40, 220), kDark(90, 90, 90);
const cv::Scalar kPalette[] = {{200, 110, 30}, {40, 40, 220}, {60, 170, 40}, {30, 150, 230}};

void text(cv::Mat& img, const std::string& s, cv::Point at, double scale = 0.5, cv::Scalar color = kBlack) {
  cv::putText(img, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, color, 1, cv::LINE_AA);
}

void save(const std::string& png, const cv::Mat& img) {
  bool ok = false;
  try {
    ok = cv::imwrite(png, img);
  } catch (const cv::Exception& e) {
    throw std::runtime_error(png + ": cannot write the picture: " + e.what());
  }
  if (!ok) throw std::runtime_error(png + ": cannot write the picture");
}

// A rectangle of the image that shows data coordinates [x0, x1] x [y0, y1], y up.
struct Axes {
  cv::Rect area;
  double x0, x1, y0, y1;
  cv::Point operator()(double x, double y) const {
    const double u = (x - x0) / std::max(x1 - x0, 1e-12), v = (y - y0) / std::max(y1 - y0, 1e-12);
    return {area.x + static_cast<int>(std::lround(u * area.width)),
            area.y + area.height - static_cast<int>(std::lround(v * area.height))};
  }
  // Frame, ticks and labels of a chart.
  void draw(cv::Mat& img, const std::string& xlabel, const std::string& ylabel, int ticks = 5) const {
    cv::rectangle(img, area, kBlack, 1);
    char buf[32];
    for (int i = 0; i <= ticks; ++i) {
      const double x = x0 + (x1 - x0) * i / ticks, y = y0 + (y1 - y0) * i / ticks;
      std::snprintf(buf, sizeof buf, "%g", std::round(x * 100) / 100);
      text(img, buf, (*this)(x, y0) + cv::Point(-10, 18), 0.4);
      std::snprintf(buf, sizeof buf, "%g", std::round(y * 100) / 100);
      text(img, buf, (*this)(x0, y) + cv::Point(-42, 4), 0.4);
    }
    text(img, xlabel, cv::Point(area.x + area.width / 2 - 40, area.y + area.height + 38));
    text(img, ylabel, cv::Point(area.x - 50, area.y - 10));
  }
};

void scale_bar(cv::Mat& img, double pixels_per_m) {
  double len = 10;
  for (double c : {10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0})
    if (c * pixels_per_m <= 160) len = c;
  const cv::Point a(20, img.rows - 20), b(20 + static_cast<int>(len * pixels_per_m), img.rows - 20);
  cv::line(img, a, b, kBlack, 2);
  text(img, std::to_string(static_cast<int>(len)) + " m", a + cv::Point(0, -8));
}

}  // namespace

void plot_trajectory(const std::string& png, const std::vector<Eigen::Vector3d>& map_trajectory,
                     const std::vector<QueryOutcome>& outcomes, const std::string& title) {
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  auto grow = [&](const Eigen::Vector3d& p) {
    x0 = std::min(x0, p.x()), x1 = std::max(x1, p.x()), y0 = std::min(y0, p.y()), y1 = std::max(y1, p.y());
  };
  for (const auto& p : map_trajectory) grow(p);
  for (const auto& o : outcomes) grow(o.truth_xy);
  if (x0 > x1) x0 = y0 = 0, x1 = y1 = 1;
  const double span = std::max({x1 - x0, y1 - y0, 1.0}), ppm = 900.0 / span;
  cv::Mat img(1000, 1000, CV_8UC3, kWhite);
  const Axes ax{cv::Rect(50, 50, static_cast<int>((x1 - x0) * ppm), static_cast<int>((y1 - y0) * ppm)), x0, x1, y0, y1};
  for (size_t i = 1; i < map_trajectory.size(); ++i)
    cv::line(img, ax(map_trajectory[i - 1].x(), map_trajectory[i - 1].y()),
             ax(map_trajectory[i].x(), map_trajectory[i].y()), kGrey, 5, cv::LINE_AA);
  for (size_t i = 1; i < outcomes.size(); ++i)
    cv::line(img, ax(outcomes[i - 1].truth_xy.x(), outcomes[i - 1].truth_xy.y()),
             ax(outcomes[i].truth_xy.x(), outcomes[i].truth_xy.y()), kLightBlue, 2, cv::LINE_AA);
  for (const QueryOutcome& o : outcomes) {
    const cv::Point t = ax(o.truth_xy.x(), o.truth_xy.y());
    if (!o.localized) {
      cv::circle(img, t, 2, kDark, cv::FILLED);
    } else if (o.correct) {
      cv::circle(img, t, 5, kGreen, cv::FILLED, cv::LINE_AA);
    } else {
      const cv::Point e = ax(o.estimate_xy.x(), o.estimate_xy.y());
      cv::line(img, t, e, kRed, 1, cv::LINE_AA);
      cv::drawMarker(img, e, kRed, cv::MARKER_TILTED_CROSS, 12, 2);
    }
  }
  text(img, title, cv::Point(20, 28), 0.6);
  text(img, "grey: map trajectory   blue: query path   green: correct   red x: false   dot: not localized",
       cv::Point(20, 985 - 40), 0.45);
  scale_bar(img, ppm);
  save(png, img);
}

void plot_px(const std::string& png, const PxCurve& c, const std::string& title) {
  const double xmax = std::max(
      10.0,
      std::ceil((c.gaps_m.empty() ? 10.0 : *std::max_element(c.gaps_m.begin(), c.gaps_m.end())) / 10.0) * 10.0 + 10.0);
  cv::Mat img(500, 700, CV_8UC3, kWhite);
  const Axes ax{cv::Rect(80, 70, 580, 355), 0.0, xmax, 0.0, 1.0};
  ax.draw(img, "x: distance travelled without localization (m)", "P(x)");
  cv::Point prev = ax(0, c.p_of(0));
  for (int i = 1; i <= 400; ++i) {
    const double x = xmax * i / 400;
    const cv::Point p = ax(x, c.p_of(x));
    cv::line(img, prev, p, kPalette[0], 2, cv::LINE_AA);
    prev = p;
  }
  cv::line(img, ax(0, 0.05), ax(xmax, 0.05), kGrey, 1);
  cv::line(img, ax(c.x95_m, 0), ax(c.x95_m, 1), kRed, 1);
  char buf[96];
  std::snprintf(buf, sizeof buf, "95%% of %.0f m within %.0f m of a localization", c.total_m, c.x95_m);
  text(img, buf, ax(c.x95_m, 0.9) + cv::Point(6, 0), 0.45, kRed);
  text(img, title, cv::Point(20, 28), 0.6);
  save(png, img);
}

void plot_error_histogram(const std::string& png, const std::vector<QueryOutcome>& outcomes, const std::string& title) {
  std::vector<double> cm;
  for (const QueryOutcome& o : outcomes)
    if (o.correct) cm.push_back(o.error_m * 100.0);
  const double top = cm.empty() ? 10.0 : std::max(10.0, std::ceil(*std::max_element(cm.begin(), cm.end()) / 5.0) * 5.0);
  const int bins = 20;
  std::vector<int> count(bins, 0);
  for (double e : cm) ++count[std::min(bins - 1, static_cast<int>(e / top * bins))];
  const int most = std::max(1, *std::max_element(count.begin(), count.end()));
  cv::Mat img(500, 700, CV_8UC3, kWhite);
  const Axes ax{cv::Rect(80, 70, 580, 355), 0.0, top, 0.0, static_cast<double>(most)};
  ax.draw(img, "translation error of correct localizations (cm)", "queries");
  for (int b = 0; b < bins; ++b)
    if (count[b] > 0)
      cv::rectangle(img, ax(top * b / bins, count[b]), ax(top * (b + 1) / bins, 0) + cv::Point(-1, 0), kPalette[0],
                    cv::FILLED);
  text(img, title, cv::Point(20, 28), 0.6);
  save(png, img);
}

void plot_roc(const std::string& png, const std::vector<RocCurve>& curves, const std::string& title) {
  cv::Mat img(600, 650, CV_8UC3, kWhite);
  const Axes ax{cv::Rect(80, 70, 500, 430), 0.0, 1.0, 0.0, 1.0};
  ax.draw(img, "false positive rate", "true positive rate");
  cv::line(img, ax(0, 0), ax(1, 1), kGrey, 1);
  for (size_t k = 0; k < curves.size(); ++k) {
    const RocCurve& c = curves[k];
    const cv::Scalar color = kPalette[k % 4];
    for (size_t i = 1; i < c.fpr.size(); ++i)
      cv::line(img, ax(c.fpr[i - 1], c.tpr[i - 1]), ax(c.fpr[i], c.tpr[i]), color, 2, cv::LINE_AA);
    cv::circle(img, ax(c.operating_fpr, c.operating_tpr), 5, color, cv::FILLED, cv::LINE_AA);
    char buf[96];
    std::snprintf(buf, sizeof buf, "%s (TPR %.2f at FPR %.2f)", c.name.c_str(), c.operating_tpr, c.operating_fpr);
    text(img, buf, ax(0.35, 0.05 + 0.07 * k), 0.45, color);
  }
  text(img, title, cv::Point(20, 28), 0.6);
  save(png, img);
}

}  // namespace eval
}  // namespace segmatch
