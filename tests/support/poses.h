// Poses for tests: a position and a heading, as generated scenes need them.
#pragma once

#include "segmatch/core/common/types.h"

#include <cmath>

namespace segmatch::test {

// T_world_x at (x, y, z) turned yaw_deg about z.
inline Pose3d pose_at(double x, double y, double z = 0.0, double yaw_deg = 0.0) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

// Around a 100 m x 60 m block twice, 1 m steps, turning left at the corners: 640 poses (the
// pose-graph tests' closed route).
inline Poses block_loop() {
  Poses out;
  Pose3d T = Pose3d::Identity();
  for (int lap = 0; lap < 2; ++lap)
    for (double side : {100.0, 60.0, 100.0, 60.0}) {
      for (int k = 0; k < static_cast<int>(side); ++k) {
        out.push_back(T);
        T = T * pose_at(1.0, 0, 0, 0);
      }
      T = T * pose_at(0, 0, 0, 90);
    }
  return out;
}

}  // namespace segmatch::test
