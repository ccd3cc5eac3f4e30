// Pre-processing of the local cloud before segmentation (paper section III-A):
//   voxel grid  - "a voxel grid is applied ... to filter-out noise in voxels where there is
//                  not enough evidence for occupancy" (leaf 0.1 m, >= 2 points, section IV-A);
//   ground      - "the ground plane [is] previously removed, which can be achieved by
//                  clustering adjacent voxels based on vertical means and variances"
//                  (Douillard et al. 2011); on KITTI "by directly filtering the input scan by
//                  minimum height" (section IV-A).
#pragma once

#include <cstdint>
#include <vector>

#include "segmatch/core/common/types.h"

namespace segmatch {

struct VoxelGridConfig {
  float leaf_m = 0.1f;           // voxel edge length (paper IV-A: 0.1 m)
  int min_points_per_voxel = 2;  // a voxel is occupied with at least this many points (IV-A: 2)
  void validate() const;         // throws std::invalid_argument naming the field
};

// One point per occupied voxel: the centroid of its points (intensity averaged). If labels
// are given (same size as cloud) the majority non-zero label of each voxel (ties: smaller
// label; 0 if none) goes to labels_out. Output sorted by voxel key (x, then y, then z), so it
// is deterministic. Non-finite points are ignored.
PointCloud voxel_filter(const PointCloud& cloud, const VoxelGridConfig& config,
                        const std::vector<uint32_t>* labels = nullptr, std::vector<uint32_t>* labels_out = nullptr);

enum class GroundRemoval {
  kNone,             // keep every point
  kHeightThreshold,  // KITTI (paper IV-A): drop points below a height relative to the sensor
  kColumnVariance,   // Douillard et al. 2011: flat, low columns of the cloud are ground
};

struct GroundConfig {
  GroundRemoval method = GroundRemoval::kColumnVariance;

  // --- kHeightThreshold: remove points with z < sensor z - sensor_height_m + this.
  float height_above_ground_m = 0.3f;
  float sensor_height_m = 1.73f;  // KITTI HDL-64E mounting height

  // --- kColumnVariance. The plane is cut into square columns; per column the vertical
  // spread (max - min) and standard deviation of z are computed.
  // Horizontal column edge. 0.5 m holds a few 0.1 m voxels per axis, yet is narrow enough
  // that poles and car sides make their columns non-flat.
  float column_size_m = 0.5f;
  // A column is flat if max - min <= this and stddev <= max_column_stddev_m. 0.3 m
  // swallows 0.15 m kerbs plus sensor noise, so kerbs are removed with the road.
  float max_column_spread_m = 0.3f;
  float max_column_stddev_m = 0.1f;
  // Lower envelope: the lowest point among columns within about this horizontal distance
  // (square tiles of this size, 3 x 3 tiles). 2 m reaches past the half width of a car, so
  // a car roof never looks low.
  float envelope_tile_m = 2.0f;
  // Flat columns whose mean is at most this above the lower envelope seed the ground. On a
  // 4 % grade the envelope can be ~0.17 m below the column; + kerb 0.15 m + noise.
  float seed_tolerance_m = 0.4f;
  // Ground grows from the seeds into 8-connected flat columns whose mean heights differ by
  // at most this (0.5 m at 4 % = 0.02 m; a kerb inside one step is 0.15 m).
  float max_step_m = 0.2f;
  // In non-ground columns (cars, trunks, walls standing on the road) points lower than the
  // estimated ground (mean of nearby ground columns) + this are removed too. 0.1 m is
  // ~3 sigma of the range noise; more would eat into the bottom of objects.
  float ground_margin_m = 0.1f;
  // How far (in columns) to look for ground columns around a non-ground column.
  int max_search_rings = 4;

  void validate() const;  // throws std::invalid_argument naming the field
};

// Removes ground points. sensor_position: world-frame position of the sensor (used by the
// height threshold only). Labels (if given, same size as cloud) of the kept points go to
// labels_out. Kept points keep their input order.
PointCloud remove_ground(const PointCloud& cloud, const GroundConfig& config, const Eigen::Vector3f& sensor_position,
                         const std::vector<uint32_t>* labels = nullptr, std::vector<uint32_t>* labels_out = nullptr);

// The same decision as a mask (true = ground), for callers that need indices.
std::vector<bool> ground_mask(const PointCloud& cloud, const GroundConfig& config,
                              const Eigen::Vector3f& sensor_position);

}  // namespace segmatch
