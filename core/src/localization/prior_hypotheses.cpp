// The verified hypotheses against a prior and against each other (Localizer::localize_segments;
// beyond the paper): which a prior allows, which explains the query best, where each query
// segment may find its map segment under a prior, and the direction a query spreads along.
// Private to the core.
#include "localization/localizer_stages.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>

namespace segmatch {
namespace detail {

Ranked rank_by_support(const std::vector<PoseHypothesis>& hypotheses, const Segments& query, const CentroidIndex& map,
                       float radius_m) {
  Ranked r;
  for (size_t h = 0; h < hypotheses.size(); ++h) {
    Support s = support_of(query, map, hypotheses[h].T_target_query, radius_m);
    if (h == 0 || s.count() > r.support.count()) {
      if (h > 0) r.runner_up = std::max(r.runner_up, r.support.count());
      r.best = h;
      r.support = std::move(s);
    } else {
      r.runner_up = std::max(r.runner_up, s.count());
    }
  }
  return r;
}

// The hypotheses that put the sensor within the prior's radius and turn it by at most the
// prior's max_rotation_deg (all of them without a prior). The turn was once left unchecked: on
// hku-mb, priors 6 m off gave poses turned 11-17 deg (docs/how-defaults-were-chosen.md).
std::vector<PoseHypothesis> within_prior(std::vector<PoseHypothesis> hypotheses, const Eigen::Vector3f& sensor,
                                         const PosePrior* prior) {
  if (!prior) return hypotheses;
  const Eigen::Vector3d s = sensor.cast<double>(), expected = prior->T_map_query * s;
  const double max_turn = prior->max_rotation_deg * M_PI / 180.0;
  std::vector<PoseHypothesis> kept;
  for (PoseHypothesis& h : hypotheses) {
    const double turn = Eigen::AngleAxisd(h.T_target_query.linear() * prior->T_map_query.linear().transpose()).angle();
    if ((h.T_target_query * s - expected).norm() <= prior->radius_m && turn <= max_turn) kept.push_back(std::move(h));
  }
  return kept;
}

// The direction the query's segments spread along under a pose, horizontally (the street's,
// for a local cloud driven along one): the principal axis of their centroids.
Eigen::Vector3d spread_axis(const Segments& query, const Pose3d& T_map_query) {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const Segment& q : query) mean += (T_map_query * q.centroid.cast<double>()).head<2>();
  if (query.empty()) return Eigen::Vector3d::UnitX();
  mean /= static_cast<double>(query.size());
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
  for (const Segment& q : query) {
    const Eigen::Vector2d d = (T_map_query * q.centroid.cast<double>()).head<2>() - mean;
    cov += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(cov);
  const Eigen::Vector2d axis = solver.eigenvectors().col(1);
  return {axis.x(), axis.y(), 0.0};
}

// Per query segment, the map segments lying where the prior, within its tolerances, puts it
// (see PosePrior). Targets are first cut to the horizontal disc that can hold any of them.
std::vector<std::vector<int>> targets_near_prior(const Segments& query, const Segments& targets,
                                                 const Eigen::Vector3f& sensor, const PosePrior& prior) {
  const double angle = prior.max_rotation_deg * M_PI / 180.0;
  const Eigen::Vector3d s = sensor.cast<double>(), s_map = prior.T_map_query * s;
  double reach = 0.0;
  for (const Segment& q : query) reach = std::max(reach, (q.centroid.cast<double>() - s).norm());
  const std::vector<int> nearby = targets_within_disc(targets, s_map, reach * (1.0 + angle) + prior.radius_m);
  std::vector<std::vector<int>> allowed(query.size());
  for (size_t qi = 0; qi < query.size(); ++qi) {
    const Eigen::Vector3d q = query[qi].centroid.cast<double>();
    const Eigen::Vector3d expected = prior.T_map_query * q;
    const double slack = prior.radius_m + angle * (q - s).norm();
    for (int t : nearby)
      if ((targets[static_cast<size_t>(t)].centroid.cast<double>() - expected).norm() <= slack)
        allowed[qi].push_back(t);
  }
  return allowed;
}

}  // namespace detail
}  // namespace segmatch
