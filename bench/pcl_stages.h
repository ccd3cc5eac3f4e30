// The stock PCL stages the original SegMatch (ETH ASL, 2017) ran per query, timed on our own
// point clouds, and the table segmatch-bench prints of PCL / ours for each stage. Only this
// pair of files includes PCL headers; the interface speaks segmatch types. Every PCL timing
// excludes the conversion to pcl::PointCloud<pcl::PointXYZ>.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/segmentation/segment.h"

#include <chrono>
#include <cstddef>
#include <vector>

namespace segmatch::bench {

// Milliseconds since t.
double ms_since(std::chrono::steady_clock::time_point t);
// Quantile q in [0, 1], linear between order statistics; NaN for no data.
double quantile(std::vector<double> values, double q);
inline double median(const std::vector<double>& values) { return quantile(values, 0.5); }

struct PclTiming {
  double ms = 0;         // wall-clock time of the PCL call(s)
  size_t outputs = 0;    // points kept / clusters found / segments described
  bool refused = false;  // PCL declined the input (e.g. voxel indices would overflow)
};

// pcl::VoxelGrid<PointXYZ> with setLeafSize(leaf) and setMinimumPointsNumberPerVoxel(min_points).
PclTiming pcl_voxel_grid(const PointCloud& cloud, float leaf_m, int min_points);

// pcl::search::KdTree build + pcl::EuclideanClusterExtraction (as the original did per query).
PclTiming pcl_euclidean_clusters(const PointCloud& cloud, float tolerance_m, int min_points, int max_points);

// pcl::ESFEstimation<PointXYZ, ESFSignature640> on each of `segments` (PCL's fixed 20000
// triples). Callers pass only segments our ESF found non-degenerate: PCL loops forever on
// segments without a proper triangle (e.g. collinear points).
PclTiming pcl_esf(const std::vector<const PointCloud*>& segments);

// Our voxel grid, Euclidean segmenter and ESF next to PCL's, cloud by cloud, all on the same
// input: the query cloud for the voxel grid, our voxelized ground-free cloud for clustering,
// our segments for ESF. Segments our ESF finds degenerate are left out of both ESF timings.
class StageComparison {
 public:
  // cloud and sensor in one frame; config as the localizer uses it.
  void run(const PointCloud& cloud, const Eigen::Vector3f& sensor, const SegmentationConfig& config);
  // Medians per cloud and PCL / ours, one line per stage.
  void print(const char* title, const SegmentationConfig& config) const;

 private:
  std::vector<double> voxel_ours_, voxel_pcl_, cluster_ours_, cluster_pcl_, esf_ours_, esf_ours_20k_, esf_pcl_;
  std::vector<double> points_ours_, points_pcl_, clusters_ours_, clusters_pcl_, esf_segments_;
  bool voxel_refused_ = false;
};

}  // namespace segmatch::bench
