// The residuals of the pose graph (Ceres auto-diff functors). Internal to pose_graph.cpp.
#pragma once

#include "segmatch/posegraph/pose_graph.h"

#include <Eigen/Geometry>

namespace segmatch::posegraph {

// The residual of an edge: a measured relative pose (p_ab, q_ab) against the estimated
// T_world_a^-1 * T_world_b, whitened. Translation in a's frame, then 2 * the vector part of the
// rotation difference (Ceres' pose_graph_3d example).
template <typename T>
void relative_pose_residual(const T* p_a_ptr, const T* q_a_ptr, const T* p_b_ptr, const T* q_b_ptr,
                            const Eigen::Matrix<T, 3, 1>& p_ab, const Eigen::Quaternion<T>& q_ab,
                            const Matrix6d& sqrt_information, T* residual_ptr) {
  const Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_a(p_a_ptr), p_b(p_b_ptr);
  const Eigen::Map<const Eigen::Quaternion<T>> q_a(q_a_ptr), q_b(q_b_ptr);
  const Eigen::Quaternion<T> q_a_inverse = q_a.conjugate();
  const Eigen::Quaternion<T> delta_q = q_ab * (q_a_inverse * q_b).conjugate();
  Eigen::Map<Eigen::Matrix<T, 6, 1>> residual(residual_ptr);
  residual.template head<3>() = q_a_inverse * (p_b - p_a) - p_ab;
  residual.template tail<3>() = T(2.0) * delta_q.vec();
  residual.applyOnTheLeft(sqrt_information.template cast<T>());
}

// One edge with its measurement as given.
struct RelativePoseError {
  RelativePoseError(const Pose3d& T_ab, const Matrix6d& sqrt_info)
      : p_ab(T_ab.translation()), q_ab(T_ab.linear()), sqrt_information(sqrt_info) {}

  template <typename T>
  bool operator()(const T* p_a, const T* q_a, const T* p_b, const T* q_b, T* residual) const {
    relative_pose_residual<T>(p_a, q_a, p_b, q_b, p_ab.template cast<T>(), q_ab.template cast<T>(), sqrt_information,
                              residual);
    return true;
  }

  Eigen::Vector3d p_ab;
  Eigen::Quaterniond q_ab;
  Matrix6d sqrt_information;
};

// A node's "up" direction in its own frame against the odometry's: roll and pitch only, yaw
// is free (2 dof; the third component is second order).
struct GravityError {
  GravityError(const Eigen::Vector3d& up_in_node, double sigma_rad) : up(up_in_node), weight(1.0 / sigma_rad) {}
  template <typename T>
  bool operator()(const T* q_ptr, T* residual_ptr) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_ptr);
    const Eigen::Matrix<T, 3, 1> estimated = q.conjugate() * Eigen::Matrix<T, 3, 1>(T(0), T(0), T(1));
    Eigen::Map<Eigen::Matrix<T, 3, 1>> residual(residual_ptr);
    residual = (estimated - up.template cast<T>()) * T(weight);
    return true;
  }
  Eigen::Vector3d up;
  double weight;
};

// An odometry edge whose measurement carries a slowly varying bias (bias[0]: yaw rate, rad per
// metre; bias[1]: climb, metres per metre; bias[2]: scale), removed before comparing: the
// measured step is shortened by the fraction bias[2], turned back by bias[0] * d about its z
// axis and lowered by bias[1] * d. Odometry errors are
// correlated along a route (a gyro bias, a miscalibrated mount), which white per-step noise
// cannot express: with it, the optimiser spreads a loop's correction as a drift would have made
// it, not as the smallest change.
struct BiasedRelativePoseError {
  BiasedRelativePoseError(const Pose3d& T_ab, const Matrix6d& sqrt_info)
      : p_ab(T_ab.translation()), q_ab(T_ab.linear()), d(T_ab.translation().norm()), sqrt_information(sqrt_info) {}

  template <typename T>
  bool operator()(const T* p_a, const T* q_a, const T* p_b, const T* q_b, const T* bias, T* residual) const {
    const T half = -bias[0] * T(d) * T(0.5);
    const Eigen::Quaternion<T> unturn(cos(half), T(0), T(0), sin(half));
    Eigen::Matrix<T, 3, 1> p_measured = p_ab.template cast<T>() * (T(1) - bias[2]);
    p_measured.z() -= bias[1] * T(d);
    relative_pose_residual<T>(p_a, q_a, p_b, q_b, p_measured, unturn * q_ab.template cast<T>(), sqrt_information,
                              residual);
    return true;
  }

  Eigen::Vector3d p_ab;
  Eigen::Quaterniond q_ab;
  double d;
  Matrix6d sqrt_information;
};

// The bias of one stretch against the next (a random walk) or against zero (the first):
// yaw rate, climb, scale, each whitened by its own sigma.
struct BiasStep {
  explicit BiasStep(const Eigen::Vector3d& sigmas) : w(sigmas.cwiseInverse()) {}
  template <typename T>
  bool operator()(const T* a, const T* b, T* residual) const {
    for (int k = 0; k < 3; ++k) residual[k] = (b[k] - a[k]) * T(w[k]);
    return true;
  }
  Eigen::Vector3d w;
};
struct BiasPrior {
  explicit BiasPrior(const Eigen::Vector3d& sigmas) : w(sigmas.cwiseInverse()) {}
  template <typename T>
  bool operator()(const T* b, T* residual) const {
    for (int k = 0; k < 3; ++k) residual[k] = b[k] * T(w[k]);
    return true;
  }
  Eigen::Vector3d w;
};

}  // namespace segmatch::posegraph
