#include "segmatch/eval/metrics.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>

namespace segmatch {
namespace eval {

void score(QueryOutcome& o, const Pose3d& T_map_sensor_estimate, const Pose3d& T_map_sensor_truth,
           const Thresholds& t) {
  o.truth_xy = T_map_sensor_truth.translation();
  if (!o.localized) return;
  o.estimate_xy = T_map_sensor_estimate.translation();
  o.T_map_sensor = T_map_sensor_estimate;
  o.error_m = (T_map_sensor_estimate.translation() - T_map_sensor_truth.translation()).norm();
  const Eigen::Matrix3d dR = T_map_sensor_estimate.linear().transpose() * T_map_sensor_truth.linear();
  o.error_deg = Eigen::AngleAxisd(dR).angle() * 180.0 / M_PI;
  o.correct = o.error_m <= t.false_translation_m && o.error_deg <= t.false_rotation_deg;
}

void score_covariance(QueryOutcome& o, const Eigen::Matrix<double, 6, 6>& covariance) {
  o.has_covariance = false;
  if (!o.localized || covariance.isZero()) return;
  const Eigen::Matrix2d horizontal = covariance.block<2, 2>(3, 3);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(horizontal);
  if (!(solver.eigenvalues()(0) > 0.0)) return;
  const Eigen::Vector2d e = (o.estimate_xy - o.truth_xy).head<2>();
  o.has_covariance = true;
  o.sigma_h_m = std::sqrt(solver.eigenvalues()(1));
  o.mahalanobis_h = std::sqrt(e.dot(horizontal.ldlt().solve(e)));
}

Distribution distribution_of(std::vector<double> v) {
  Distribution d;
  d.count = v.size();
  if (v.empty()) return d;
  std::sort(v.begin(), v.end());
  auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))]; };
  d.median = at(0.5);
  d.p90 = at(0.9);
  d.max = v.back();
  d.mean = std::accumulate(v.begin(), v.end(), 0.0) / v.size();
  return d;
}

double PxCurve::p_of(double x) const {
  if (total_m <= 0.0) return 0.0;
  double sum = 0.0;
  for (double g : gaps_m) sum += g >= x ? g : 0.0;
  return sum / total_m;
}

PxCurve px_curve(const std::vector<QueryOutcome>& outcomes) {
  PxCurve c;
  double gap = 0.0;
  for (size_t i = 0; i < outcomes.size(); ++i) {
    // The stretch since the previous query counts towards the running gap if it was mapped.
    const double step = i == 0 ? 0.0 : outcomes[i].odometer_m - outcomes[i - 1].odometer_m;
    if (outcomes[i].mapped) {
      gap += step;
      c.total_m += step;
    }
    if (outcomes[i].correct) {
      if (gap > 0.0) c.gaps_m.push_back(gap);
      gap = 0.0;
    }
  }
  if (gap > 0.0) c.gaps_m.push_back(gap);
  // P is a step function falling at each gap length: the smallest x with P(x) <= 0.05 is just
  // above the longest gap whose removal brings the remaining long gaps under 5 %.
  std::vector<double> sorted = c.gaps_m;
  std::sort(sorted.begin(), sorted.end(), std::greater<double>());
  double above = 0.0;
  c.x95_m = 0.0;
  for (double g : sorted) {
    if ((above + g) > 0.05 * c.total_m) {
      c.x95_m = g;
      break;
    }
    above += g;
  }
  return c;
}

Summary summarize(const std::vector<QueryOutcome>& outcomes) {
  Summary s;
  std::vector<double> err_m, err_deg, latency, sigma_h;
  for (const QueryOutcome& o : outcomes) {
    ++s.queries;
    s.mapped_queries += o.mapped;
    latency.push_back(o.latency_ms);
    if (!o.localized) continue;
    s.rejected += o.rejected;
    s.rejected_false += o.rejected && !o.correct;
    ++s.localized;
    ++s.localized_by_method[o.method.empty() ? "unknown" : o.method];
    if (o.has_covariance) {
      ++s.with_covariance;
      s.within_3_sigma += o.mahalanobis_h <= 3.0;
      sigma_h.push_back(o.sigma_h_m);
    }
    if (o.correct) {
      ++s.correct;
      err_m.push_back(o.error_m);
      err_deg.push_back(o.error_deg);
    } else {
      ++s.false_localizations;
    }
  }
  s.error_m = distribution_of(err_m);
  s.error_deg = distribution_of(err_deg);
  s.latency_ms = distribution_of(latency);
  s.px = px_curve(outcomes);
  s.sigma_h_m = distribution_of(sigma_h);
  return s;
}

}  // namespace eval
}  // namespace segmatch
