// Plain value types that flow between the stages of the pipeline.
//
// Poses are named by frames: T_a_b maps a point expressed in frame b into frame a
// (p_a = T_a_b * p_b), so T_a_c = T_a_b * T_b_c reads left to right.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <vector>

namespace segmatch {

// One LiDAR return. Layout matches a KITTI velodyne record (4 x float32), so a scan can be
// written or read as one block.
struct Point {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
  float intensity = 0.0f;

  Eigen::Vector3f xyz() const { return {x, y, z}; }
};
static_assert(sizeof(Point) == 16, "Point must stay 4 packed floats");

using PointCloud = std::vector<Point>;

// Rigid transform in double precision (poses accumulate over kilometres).
using Pose3d = Eigen::Isometry3d;
using Poses = std::vector<Pose3d, Eigen::aligned_allocator<Pose3d>>;

// SemanticKITTI label encoding: lower 16 bits semantic class, upper 16 bits instance id.
inline uint32_t encode_label(uint16_t semantic_class, uint16_t instance) {
  return (static_cast<uint32_t>(instance) << 16) | semantic_class;
}
inline uint16_t label_class(uint32_t label) { return static_cast<uint16_t>(label & 0xFFFFu); }
inline uint16_t label_instance(uint32_t label) { return static_cast<uint16_t>(label >> 16); }

}  // namespace segmatch
