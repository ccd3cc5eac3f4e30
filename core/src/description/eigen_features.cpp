// Eigenvalue-based segment features (Weinmann et al. 2014, "Semantic 3D scene interpretation:
// a framework combining optimal neighborhood size selection with relevant features"), as used
// by SegMatch (Dube et al. ICRA 2017, section III-C), plus the descriptor configuration and
// describe_segments(), which runs both descriptors over a set of segments.
//
// Note: the original SegMatch code sorted the eigenvalues ascending while using the formulas
// for l1 >= l2 >= l3, which swaps e.g. linearity and scattering. Here they are sorted
// descending, so a line has linearity ~1.
#include "segmatch/core/description/descriptors.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace {

// Covariance (divided by n) of the points, accumulated in double around the mean.
Eigen::Matrix3d covariance(const PointCloud& points) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Point& p : points) mean += p.xyz().cast<double>();
  mean /= static_cast<double>(points.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const Point& p : points) {
    const Eigen::Vector3d d = p.xyz().cast<double>() - mean;
    cov.noalias() += d * d.transpose();
  }
  return cov / static_cast<double>(points.size());
}

// Eigenvalues of the covariance clamped to >= 0, normalised to sum 1, sorted l[0] >= l[1] >=
// l[2]. Returns false when the covariance is (numerically) zero or not finite.
bool normalised_eigenvalues(const PointCloud& points, double l[3]) {
  const Eigen::Matrix3d cov = covariance(points);
  if (!cov.allFinite()) return false;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(cov, Eigen::EigenvaluesOnly);
  if (solver.info() != Eigen::Success) return false;
  for (int i = 0; i < 3; ++i) l[i] = std::max(0.0, solver.eigenvalues()[i]);
  std::sort(l, l + 3, [](double a, double b) { return a > b; });
  const double sum = l[0] + l[1] + l[2];
  // Identical points give an exactly zero covariance (the mean of equal floats is exact in
  // double); 1e-30 m^2 only guards against denormal noise.
  if (!(sum > 1e-30) || !std::isfinite(sum)) return false;
  for (int i = 0; i < 3; ++i) l[i] /= sum;
  return l[0] > 0.0;
}

double x_log_x(double x) { return x > 0.0 ? x * std::log(x) : 0.0; }

Eigen::Vector3f mean_of(const PointCloud& points) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Point& p : points) sum += p.xyz().cast<double>();
  return (sum / static_cast<double>(points.size())).cast<float>();
}

}  // namespace

void DescriptorConfig::validate() const {
  if (esf_samples <= 0) {
    throw std::invalid_argument("DescriptorConfig.esf_samples must be > 0, got " + std::to_string(esf_samples));
  }
}

EigenFeatures eigen_features(const PointCloud& points) {
  EigenFeatures f{};
  double l[3];
  if (points.size() < 3 || !normalised_eigenvalues(points, l)) return f;
  const double sum = l[0] + l[1] + l[2];  // 1 up to rounding
  const double values[kEigenFeatureCount] = {
      (l[0] - l[1]) / l[0],                              // linearity
      (l[1] - l[2]) / l[0],                              // planarity
      l[2] / l[0],                                       // scattering
      std::cbrt(l[0] * l[1] * l[2]),                     // omnivariance
      (l[0] - l[2]) / l[0],                              // anisotropy
      -(x_log_x(l[0]) + x_log_x(l[1]) + x_log_x(l[2])),  // eigenentropy
      l[2] / sum,                                        // change of curvature
  };
  for (int i = 0; i < kEigenFeatureCount; ++i) {
    if (!std::isfinite(values[i])) return EigenFeatures{};
    f[static_cast<size_t>(i)] = static_cast<float>(values[i]);
  }
  return f;
}

void describe_segments(Segments& segments, const DescriptorConfig& config, const Deadline& deadline) {
  config.validate();
  for (Segment& segment : segments) {
    if (deadline.passed()) return;
    if (!segment.points.empty() && segment.centroid.isZero(0.0f)) {
      segment.centroid = mean_of(segment.points);
    }
    if (config.compute_eigen) {
      segment.eigen = eigen_features(segment.points);
      segment.has_eigen = true;
    }
    if (config.compute_esf) {
      // Same seed for every segment: the descriptor depends on the points only.
      segment.esf = esf_descriptor(segment.points, config.esf_samples, config.esf_seed);
      segment.has_esf = true;
    }
  }
}

}  // namespace segmatch
