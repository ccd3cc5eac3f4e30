// Poses for tests: a position and a heading, as generated scenes need them.
#pragma once

#include "segmatch/core/types.h"

#include <cmath>

namespace segmatch::test {

// T_world_x at (x, y, z) turned yaw_deg about z.
inline Pose3d pose_at(double x, double y, double z = 0.0, double yaw_deg = 0.0) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

}  // namespace segmatch::test
