// Segmentation of the voxelized, ground-free local cloud into segments (paper III-A):
// "Euclidean clustering is used for growing segments" - occupied voxels closer than 0.2 m
// join one cluster, and only clusters of 100 .. 15000 points are kept (section IV-A).
// Alternative: region growing with a smoothness constraint (Rabbani et al. 2006), which
// also splits touching surfaces whose normals differ (a wall and a slab against it).
// For one raw scan of a spinning sensor: range-image segmentation (Bogoslavskyi & Stachniss,
// "Fast range image-based segmentation of sparse 3D laser scans for online operation", IROS
// 2016), which uses the scan's structure that voxels and Euclidean distances lose.
#pragma once

#include <cstdint>
#include <vector>

#include "segmatch/core/common/types.h"
#include "segmatch/core/segmentation/segment.h"

namespace segmatch {

enum class SegmenterType {
  kEuclidean,      // paper III-A: Euclidean clustering of occupied voxels
  kRegionGrowing,  // Rabbani et al. 2006: Euclidean neighbours with similar normals
  // Bogoslavskyi & Stachniss 2016: connected components of the raw scan's range image. Only a
  // raw single scan has a range image: extract_segments() uses it when the scan's elevations
  // show rings (or range_image_rows > 0); other clouds (voxelized, accumulated, segment_cloud)
  // are clustered as kEuclidean with the same fields.
  kRangeImage,
};

struct SegmenterConfig {
  SegmenterType type = SegmenterType::kEuclidean;
  // Two points closer than this are neighbours (paper IV-A: 0.2 m = two 0.1 m voxels).
  float cluster_distance_m = 0.2f;
  // Segments with fewer / more points are discarded (paper IV-A: 100 and 15000).
  int min_points = 100;
  int max_points = 15000;

  // --- kRegionGrowing only.
  // Radius of the neighbourhood whose covariance gives each point's normal and curvature;
  // 0.3 m covers about three voxel rings, enough to average out ~3 cm range noise.
  float normal_radius_m = 0.3f;
  // A neighbour joins the region if its normal is within this angle of the current seed's
  // (Rabbani's smoothness constraint). 10 deg tolerates noisy real scans; 90 deg creases
  // (wall / slab, pole / kerb) are cut.
  float max_normal_angle_deg = 10.0f;
  // A point that joined a region grows it further only if its curvature
  // lambda_min / (lambda_0 + lambda_1 + lambda_2) is below this (a plane is ~0, an
  // isotropic blob 1/3); points on creases join but do not propagate.
  float max_curvature = 0.1f;
  // Points with fewer neighbours within normal_radius_m (self included) get no normal and
  // never join a region grown from another point.
  int min_normal_neighbours = 5;

  // --- kRangeImage only (Bogoslavskyi & Stachniss 2016).
  // Two neighbouring pixels are one object if the angle beta at the nearer point, between its
  // beam and the line to the farther point, exceeds this (paper IV: 10 deg). A surface seen
  // at a grazing angle below beta is cut; a depth jump behind an edge gives a small beta.
  float range_image_beta_deg = 10.0f;
  // Rows. 0: one per ring of the sensor, recovered from the points' elevations seen from the
  // sensor (measure_rings, after fitting the rings' axis, which a tilted scan or vehicle
  // moves); a cloud showing no rings is clustered as kEuclidean. > 0: this many rows of equal
  // height between the lowest and the highest elevation (a sensor without rings), at most 1024;
  // every raw cloud given to extract_segments() is then taken for one scan, even an accumulated one.
  int range_image_rows = 0;
  // Column width (azimuth). 0: the median azimuth step between neighbouring points of one
  // ring (with range_image_rows > 0: the row height, square pixels). Otherwise >= 0.05 deg.
  float range_image_azimuth_step_deg = 0.0f;

  void validate() const;  // throws std::invalid_argument naming the field
};

// Segments of the cloud (expected voxelized and ground-free). Each segment holds its points
// (in input order) and their centroid. With labels (same size as cloud), Segment::label is
// the most frequent non-zero label among its points (ties: smaller label; 0 if none).
// Segment ids are 0..n-1 ordered by each segment's smallest point index. Deterministic.
// Non-finite points are ignored.
Segments segment_cloud(const PointCloud& cloud, const SegmenterConfig& config,
                       const std::vector<uint32_t>* labels = nullptr);

// --- kRangeImage: the range image of one raw scan, and its segments.

// The pixel grid of a scan seen from `sensor` (same frame as the scan's points): the rings'
// axis, the rows' elevations and the columns' width. Column 0 looks along the scan frame's x
// axis (projected across the axis); azimuth grows towards y.
struct RangeImageGrid {
  Eigen::Matrix3f to_image = Eigen::Matrix3f::Identity();  // rows: x', y', the rings' axis
  Eigen::Vector3f sensor = Eigen::Vector3f::Zero();
  std::vector<float> row_bounds_deg;  // row r spans elevations [bounds[r], bounds[r + 1])
  std::vector<float> row_phase;       // per row: azimuth offset of its points, in columns
  int columns = 0;
  float azimuth_step_deg = 0.0f;
  bool rings = false;  // rows are the sensor's rings (else rows of equal height)
  int rows() const { return row_bounds_deg.empty() ? 0 : int(row_bounds_deg.size()) - 1; }
  bool valid() const { return rows() > 0 && columns > 0; }
};

// Fits the grid to the whole raw scan (ground included: it holds the lowest rings). Invalid
// (rows() == 0) when range_image_rows is 0 and the elevations show no rings.
RangeImageGrid fit_range_image(const PointCloud& scan, const Eigen::Vector3f& sensor, const SegmenterConfig& config);

// Component of every point of `cloud` (the scan's ground-free points) in the grid's range
// image: 1.. by the first pixel of each component in row-major order; 0 for a non-finite
// point or one that shares its pixel with a nearer point it is not one object with.
std::vector<uint32_t> range_image_components(const RangeImageGrid& grid, const PointCloud& cloud,
                                             const SegmenterConfig& config);

// Segments of a cloud whose points carry a component each (0: none), e.g. the voxels of the
// labelled points (voxel_filter with the components as labels): the components of
// [min_points, max_points] points, as segment_cloud() builds, orders and labels them.
Segments segments_of_components(const PointCloud& cloud, const std::vector<uint32_t>& components,
                                const SegmenterConfig& config, const std::vector<uint32_t>* labels = nullptr);

}  // namespace segmatch
