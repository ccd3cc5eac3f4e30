// Incremental voxel grid of a local cloud (paper III-A, IV-A: 0.1 m voxels, occupied with at
// least 2 points, each voxel's point the centroid of its points), for the map builder, which
// crops and voxelizes a local cloud of millions of points every few metres.
//
// VoxelAccumulator holds the same scans as LocalCloud (same admission: min travel, optional
// subsampling, non-finite points dropped; same eviction: a scan whose horizontal bounding box
// lies wholly outside the cylinder is dropped at crop time) and gives, for every crop,
//
//     voxel_filter(LocalCloud::crop(T), voxel, labels)           (same scans, same config)
//
// up to the float rounding of the centroid sums: same voxels, same order (voxel key: x, then
// y, then z), same majority labels (non-zero majority, ties to the smaller label, 0 if none).
//
// How: the plane is cut into tiles of 16 x 16 voxel columns (1.6 m at 0.1 m), each with a
// small hash table voxel -> (count, sums of the position inside the voxel in 32.32 fixed
// point, intensity sum, label votes). Every added scan's points are summed in; a dropped scan
// is subtracted (its points are kept, world frame, grouped by tile). Fixed-point sums make
// addition and subtraction exact and order-independent, so the tables do not drift.
// The crop is exact, not by voxel centroid: voxels of tiles wholly inside the cylinder come
// from the tables, tiles wholly outside are skipped, and the voxels of the tiles the
// cylinder's boundary crosses (a ring ~1.6-2.3 m wide) are summed again from the raw points
// that pass LocalCloud's point test (horizontal distance <= radius_m). So a voxel cut by the
// boundary gets the centroid and count of its points inside, exactly as cropping raw points
// first; a crop by voxel centroid would keep or drop such a voxel whole, with all its points
// (see voxel_accumulator_test.cpp). The output comes in voxel_filter's order without a
// global sort: tiles in (x, y) order, each tile's voxels sorted by column and z, then each
// strip of tiles sharing x emitted column by column. Cost per crop: the tiles near the
// cylinder plus the raw points of the boundary ring, not the millions of points held
// (HDL-64E, 60 m, ~20 M points held: ~15 ms for 260 k voxels, segmatch-bench).
// Memory: the held scans' points (as LocalCloud) plus ~44 bytes per slot of the voxel tables
// (25-70 % used; tables mostly emptied by dropped scans are compacted).
//
// Limits: points more than 20 km (any axis) from their sensor are refused (invalid_argument);
// voxel keys wrap every 2^21 voxels (210 km at 0.1 m) and are unwrapped around the crop
// centre, so routes of any length work.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "segmatch/core/common/types.h"
#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/preprocess/preprocess.h"

namespace segmatch {

class VoxelAccumulator {
 public:
  explicit VoxelAccumulator(const LocalCloudConfig& local = {}, const VoxelGridConfig& voxel = {});
  ~VoxelAccumulator();
  VoxelAccumulator(VoxelAccumulator&&) noexcept;
  VoxelAccumulator& operator=(VoxelAccumulator&&) noexcept;

  // As LocalCloud::add_scan (the scan is also summed into the voxels). Returns whether it
  // was added.
  bool add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor,
                const std::vector<uint32_t>* labels = nullptr);

  // The voxelized cylinder around T_world_sensor: voxel_filter of LocalCloud::crop (see
  // above); drops (and subtracts) the scans wholly outside it first, as LocalCloud::crop.
  // labels_out (if given) gets each voxel's majority label (0 where none).
  PointCloud crop(const Pose3d& T_world_sensor, std::vector<uint32_t>* labels_out = nullptr);

  // Only the first step of crop: drops (and subtracts) the scans wholly outside the cylinder
  // around T_world_sensor. A vehicle that crops at its current pose may call it after every
  // add_scan: the same as cropping at every scan, and the cost of dropping old scans (a
  // subtraction per point) leaves the query.
  void evict(const Pose3d& T_world_sensor);

  size_t scan_count() const;
  size_t point_count() const;
  size_t voxel_count() const;  // voxels holding at least one point of a held scan
  void clear();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace segmatch
