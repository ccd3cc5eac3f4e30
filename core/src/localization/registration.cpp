#include "segmatch/core/localization/registration.h"

#include "segmatch/core/localization/localizer.h"  // crop_cylinder
#include "segmatch/core/preprocess/preprocess.h"   // voxel_filter

#include "detail/config_checks.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace segmatch {

void RegistrationConfig::validate() const {
  auto positive = [](float v, const char* name) { detail::require_positive(v, "RegistrationConfig", name); };
  positive(window_m, "window_m");
  positive(coarse_correspondence_m, "coarse_correspondence_m");
  positive(max_prior_radius_m, "max_prior_radius_m");
  detail::require_non_negative(coarse_leaf_m, "RegistrationConfig", "coarse_leaf_m");
  positive(max_last_step_m, "max_last_step_m");
  if (min_support < 0) throw std::invalid_argument("RegistrationConfig.min_support must be >= 0");
  if (min_matched_segments < 0) throw std::invalid_argument("RegistrationConfig.min_matched_segments must be >= 0");
  if (min_query_points < 6) throw std::invalid_argument("RegistrationConfig.min_query_points must be >= 6");
  detail::require_fraction(min_fitness, "RegistrationConfig", "min_fitness");
  if (!(min_axis_share >= 0.0f && min_axis_share <= 1.0f / 3.0f))
    throw std::invalid_argument("RegistrationConfig.min_axis_share must be in 0..1/3");
}

void NewestScansConfig::validate() const {
  auto positive = [](float v, const char* name) { detail::require_positive(v, "NewestScansConfig", name); };
  positive(window_m, "window_m");
  positive(leaf_m, "leaf_m");
  positive(max_shift_m, "max_shift_m");
  positive(max_turn_deg, "max_turn_deg");
  if (min_points < 6) throw std::invalid_argument("NewestScansConfig.min_points must be >= 6");
  detail::require_fraction(min_fitness, "NewestScansConfig", "min_fitness");
}

void SurfaceTrackingConfig::validate() const {
  auto positive = [](float v, const char* name) { detail::require_positive(v, "SurfaceTrackingConfig", name); };
  positive(leaf_m, "leaf_m");
  positive(window_m, "window_m");
  if (min_points < 6) throw std::invalid_argument("SurfaceTrackingConfig.min_points must be >= 6");
  if (max_points < min_points) throw std::invalid_argument("SurfaceTrackingConfig.max_points must be >= min_points");
  positive(ambiguity_range_m, "ambiguity_range_m");
  if (min_matched_segments < 0) throw std::invalid_argument("SurfaceTrackingConfig.min_matched_segments must be >= 0");
  if (min_matched_segments_near_prior < 0)
    throw std::invalid_argument("SurfaceTrackingConfig.min_matched_segments_near_prior must be >= 0");
  if (min_support_for_fewer_matched < 0)
    throw std::invalid_argument("SurfaceTrackingConfig.min_support_for_fewer_matched must be >= 0 (0: off)");
  detail::require_non_negative(fine_first_m, "SurfaceTrackingConfig", "fine_first_m", "(0: off)");
  detail::require_non_negative(fine_first_max_radius_m, "SurfaceTrackingConfig", "fine_first_max_radius_m");
  positive(max_shifted_support, "max_shifted_support");
  detail::require_fraction(min_fitness, "SurfaceTrackingConfig", "min_fitness");
}

void CovarianceConfig::validate() const {
  detail::require_positive(scale, "CovarianceConfig", "scale");
  detail::require_non_negative(floor_m, "CovarianceConfig", "floor_m");
  detail::require_non_negative(floor_deg, "CovarianceConfig", "floor_deg");
}

Matrix6d pose_covariance(const RefineResult& refined, const CovarianceConfig& config) {
  if (refined.plane_correspondences < 6) return Matrix6d::Zero();
  const Eigen::LDLT<Matrix6d> ldlt(refined.information);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().array() > 0.0).all()) return Matrix6d::Zero();
  const double s2 = static_cast<double>(refined.plane_rmse_m) * refined.plane_rmse_m;
  Matrix6d cov = config.scale * s2 * ldlt.solve(Matrix6d::Identity());
  if (!cov.allFinite()) return Matrix6d::Zero();
  cov = 0.5 * (cov + cov.transpose());
  const double floor_rad = config.floor_deg * M_PI / 180.0;
  cov.diagonal().head<3>().array() += floor_rad * floor_rad;
  cov.diagonal().tail<3>().array() += static_cast<double>(config.floor_m) * config.floor_m;
  return cov;
}

float weakest_axis_share(const RefineResult& refined, Eigen::Vector3d* axis) {
  if (refined.plane_correspondences < 6) return 0.0f;
  const Matrix6d& A = refined.information;
  // Schur complement: the translation information once rotation is free to absorb what it can.
  const Eigen::Matrix3d Arr = A.topLeftCorner<3, 3>() + 1e-9 * Eigen::Matrix3d::Identity();
  const Eigen::Matrix3d S =
      A.bottomRightCorner<3, 3>() - A.bottomLeftCorner<3, 3>() * Arr.ldlt().solve(A.topRightCorner<3, 3>());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(0.5 * (S + S.transpose()));
  if (axis) *axis = solver.eigenvectors().col(0);
  return static_cast<float>(std::max(0.0, solver.eigenvalues()(0)) /
                            static_cast<double>(refined.plane_correspondences));
}

namespace {

// The fine stage may need more iterations than a refinement from verified centroids: its start
// is the coarse stage's, from a prior, and it must end settled (max_last_step_m).
constexpr int kMinFineIterations = 50;

RegistrationResult refused(RegistrationResult r, RegistrationRefusal why, std::string reason) {
  r.refusal = why;
  r.reason = std::move(reason);
  return r;
}

std::string fmt(const char* format, double a, double b) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), format, a, b);
  return buf;
}

}  // namespace

RegistrationResult register_to_map(const PointCloud& query_points, const PointCloud& map_points,
                                   const Pose3d& T_map_query_prior, const Eigen::Vector3d& sensor_query,
                                   double prior_radius_m, double prior_rotation_deg, float max_rmse_m,
                                   const RegistrationConfig& config, const RefineConfig& refine,
                                   const CovarianceConfig& covariance) {
  config.validate();
  covariance.validate();
  RegistrationResult r;
  r.T_map_query = T_map_query_prior;
  if (prior_radius_m > config.max_prior_radius_m)
    return refused(r, RegistrationRefusal::kWidePrior,
                   fmt("the prior's radius %.1f m exceeds %.1f m", prior_radius_m, config.max_prior_radius_m));
  const PointCloud window = crop_cylinder(query_points, sensor_query, config.window_m);
  if (window.size() < static_cast<size_t>(config.min_query_points) || map_points.empty())
    return refused(r, RegistrationRefusal::kFewPoints,
                   fmt("%.0f query points in the window and %.0f map points near the prior", double(window.size()),
                       double(map_points.size())));
  const Eigen::Vector3d pivot_prior = T_map_query_prior * sensor_query;
  RefineConfig coarse = refine, fine_config = refine;
  coarse.max_correspondence_m = std::max(config.coarse_correspondence_m, refine.max_correspondence_m);
  fine_config.max_iterations = std::max(refine.max_iterations, kMinFineIterations);
  // The coarse stage looks 1.5 m around each query point: the map at full density only makes
  // each look slower (RegistrationConfig::coarse_leaf_m).
  PointCloud thinned;
  if (config.coarse_stage && config.coarse_leaf_m > 0.0f) {
    VoxelGridConfig thin;
    thin.leaf_m = config.coarse_leaf_m;
    thin.min_points_per_voxel = 1;
    thinned = voxel_filter(map_points, thin);
  }
  const PointCloud& coarse_map = config.coarse_leaf_m > 0.0f ? thinned : map_points;
  const Pose3d start = config.coarse_stage
                           ? refine_alignment(window, coarse_map, T_map_query_prior, coarse, pivot_prior).T_target_query
                           : T_map_query_prior;
  const RefineResult fine = refine_alignment(window, map_points, start, fine_config, start * sensor_query);
  r.T_map_query = fine.T_target_query;
  r.fitness = fine.fitness;
  r.rmse_m = fine.rmse_m;
  r.weakest_axis_share = weakest_axis_share(fine, &r.weakest_axis);
  r.covariance = pose_covariance(fine, covariance);
  // Still moving when the iterations ran out: a prior outside the basin, being dragged along.
  if (!fine.converged && fine.last_step_m > config.max_last_step_m)
    return refused(r, RegistrationRefusal::kNotConverged,
                   fmt("registration still moving %.3f m per iteration after %.0f iterations", fine.last_step_m,
                       double(fine.iterations)));
  if (fine.fitness < config.min_fitness)
    return refused(r, RegistrationRefusal::kLowFitness,
                   fmt("registration fitness %.2f below %.2f", fine.fitness, config.min_fitness));
  if (max_rmse_m > 0.0f && fine.rmse_m > max_rmse_m)
    return refused(r, RegistrationRefusal::kHighRmse,
                   fmt("registered surfaces %.3f m apart (RMS, at most %.3f)", fine.rmse_m, max_rmse_m));
  const double moved = (fine.T_target_query * sensor_query - pivot_prior).norm();
  if (moved > prior_radius_m)
    return refused(r, RegistrationRefusal::kOutsidePrior,
                   fmt("registration moved the sensor %.1f m from the prior (radius %.1f m)", moved, prior_radius_m));
  const double turned_deg =
      Eigen::AngleAxisd(fine.T_target_query.linear() * T_map_query_prior.linear().transpose()).angle() * 180.0 / M_PI;
  if (turned_deg > prior_rotation_deg)
    return refused(
        r, RegistrationRefusal::kOutsidePrior,
        fmt("registration turned the sensor %.1f deg from the prior (at most %.1f)", turned_deg, prior_rotation_deg));
  if (r.weakest_axis_share < config.min_axis_share || r.covariance.isZero())
    return refused(r, RegistrationRefusal::kDegenerate,
                   fmt("degenerate: %.3f of the surface information along the weakest axis (at least %.3f)",
                       r.weakest_axis_share, config.min_axis_share));
  r.refusal = RegistrationRefusal::kNone;
  return r;
}

}  // namespace segmatch
