// Segmentation of the voxelized, ground-free local cloud into segments (paper III-A):
// "Euclidean clustering is used for growing segments" - occupied voxels closer than 0.2 m
// join one cluster, and only clusters of 100 .. 15000 points are kept (section IV-A).
// Alternative: region growing with a smoothness constraint (Rabbani et al. 2006), which
// also splits touching surfaces whose normals differ (a wall and a slab against it).
#pragma once

#include <cstdint>
#include <vector>

#include "segmatch/core/common/types.h"
#include "segmatch/core/segmentation/segment.h"

namespace segmatch {

enum class SegmenterType {
  kEuclidean,      // paper III-A: Euclidean clustering of occupied voxels
  kRegionGrowing,  // Rabbani et al. 2006: Euclidean neighbours with similar normals
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

  void validate() const;  // throws std::invalid_argument naming the field
};

// Segments of the cloud (expected voxelized and ground-free). Each segment holds its points
// (in input order) and their centroid. With labels (same size as cloud), Segment::label is
// the most frequent non-zero label among its points (ties: smaller label; 0 if none).
// Segment ids are 0..n-1 ordered by each segment's smallest point index. Deterministic.
// Non-finite points are ignored.
Segments segment_cloud(const PointCloud& cloud, const SegmenterConfig& config,
                       const std::vector<uint32_t>* labels = nullptr);

}  // namespace segmatch
