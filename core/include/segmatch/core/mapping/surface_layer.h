// The map's surface layer (beyond the paper): every surface the mapping run saw, ground and
// walls included, thinned to one point per leaf_m voxel, map frame. The segments leave the
// ground out by design (paper III-B); registration onto segments alone then holds the height,
// roll and pitch weakly. The server registers the vehicle's newest scans onto this layer
// (Localizer, MapSurfaces); the map file stores it in tiles of tile_m.
#pragma once

#include "segmatch/core/common/types.h"

namespace segmatch {

struct SurfaceLayerConfig {
  // On: the newest scans registered onto it hold roll, pitch and height (chosen on riverside02,
  // hku-mb and the simulated demo city). Off saves the map build a voxel grid per scan and the
  // file its tiles; the server then registers onto segment points alone.
  bool enabled = true;
  float leaf_m = 0.25f;       // one point per voxel of this edge (the centroid of what fell in it)
  float max_range_m = 40.0f;  // of each scan: farther returns are sparse and noisy
  float tile_m = 64.0f;       // the map file's tiles (read on demand by a server)
  void validate() const;      // throws std::invalid_argument naming the field
};

// Accumulates scans into the layer. Each scan is thinned on its own, then the layer is thinned
// again whenever it doubled, so memory stays near the layer's final size.
class SurfaceAccumulator {
 public:
  explicit SurfaceAccumulator(const SurfaceLayerConfig& config = {});
  void add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor);
  // The layer: one point per occupied voxel (world frame), in voxel_filter's order.
  PointCloud points() const;
  size_t scans() const { return scans_; }

 private:
  SurfaceLayerConfig config_;
  PointCloud points_;
  size_t thinned_size_ = 0, scans_ = 0;
};

}  // namespace segmatch
