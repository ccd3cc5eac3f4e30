#include "pcl_stages.h"

#include <pcl/features/esf.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/extract_clusters.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>

namespace segmatch::bench {
namespace {

using Clock = std::chrono::steady_clock;

pcl::PointCloud<pcl::PointXYZ>::Ptr to_pcl(const PointCloud& cloud) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr out(new pcl::PointCloud<pcl::PointXYZ>);
  out->reserve(cloud.size());
  for (const Point& p : cloud) {
    if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) out->push_back(pcl::PointXYZ(p.x, p.y, p.z));
  }
  out->width = static_cast<uint32_t>(out->size());
  out->height = 1;
  out->is_dense = true;
  return out;
}

// Mirrors the guard in pcl::VoxelGrid::applyFilter: beyond this PCL warns and copies the input.
bool voxel_indices_overflow(const pcl::PointCloud<pcl::PointXYZ>& cloud, float leaf_m) {
  if (cloud.empty()) return false;
  Eigen::Vector3f lo = cloud[0].getVector3fMap(), hi = lo;
  for (const auto& p : cloud) {
    lo = lo.cwiseMin(p.getVector3fMap());
    hi = hi.cwiseMax(p.getVector3fMap());
  }
  const double inv = 1.0 / leaf_m;
  const auto cells = [&](int a) { return static_cast<int64_t>(std::floor((hi[a] - lo[a]) * inv)) + 1; };
  return cells(0) * cells(1) * cells(2) > static_cast<int64_t>(std::numeric_limits<int32_t>::max());
}

}  // namespace

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(pos);
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

PclTiming pcl_voxel_grid(const PointCloud& cloud, float leaf_m, int min_points) {
  const auto input = to_pcl(cloud);
  PclTiming t;
  t.refused = voxel_indices_overflow(*input, leaf_m);
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setInputCloud(input);
  grid.setLeafSize(leaf_m, leaf_m, leaf_m);
  grid.setMinimumPointsNumberPerVoxel(static_cast<unsigned int>(min_points));
  pcl::PointCloud<pcl::PointXYZ> output;
  const auto start = Clock::now();
  grid.filter(output);
  t.ms = ms_since(start);
  t.outputs = output.size();
  return t;
}

PclTiming pcl_euclidean_clusters(const PointCloud& cloud, float tolerance_m, int min_points, int max_points) {
  const auto input = to_pcl(cloud);
  PclTiming t;
  std::vector<pcl::PointIndices> clusters;
  const auto start = Clock::now();
  pcl::search::KdTree<pcl::PointXYZ>::Ptr tree(new pcl::search::KdTree<pcl::PointXYZ>);
  tree->setInputCloud(input);
  pcl::EuclideanClusterExtraction<pcl::PointXYZ> extraction;
  extraction.setClusterTolerance(tolerance_m);
  extraction.setMinClusterSize(min_points);
  extraction.setMaxClusterSize(max_points);
  extraction.setSearchMethod(tree);
  extraction.setInputCloud(input);
  extraction.extract(clusters);
  t.ms = ms_since(start);
  t.outputs = clusters.size();
  return t;
}

PclTiming pcl_esf(const std::vector<const PointCloud*>& segments) {
  PclTiming t;
  // One estimator for all segments, as the original's EnsembleShapeFunctions member: its
  // 64^3 lookup table is allocated once, outside the timing.
  pcl::ESFEstimation<pcl::PointXYZ, pcl::ESFSignature640> esf;
  pcl::PointCloud<pcl::ESFSignature640> signature;
  for (const PointCloud* segment : segments) {
    const auto input = to_pcl(*segment);
    if (input->size() < 3) continue;
    const auto start = Clock::now();
    esf.setInputCloud(input);
    esf.compute(signature);
    t.ms += ms_since(start);
    t.outputs += signature.size() == 1;
  }
  return t;
}

void StageComparison::run(const PointCloud& cloud, const Eigen::Vector3f& sensor, const SegmentationConfig& c) {
  auto t0 = Clock::now();
  const PointCloud voxels = voxel_filter(cloud, c.voxel);
  voxel_ours_.push_back(ms_since(t0));
  points_ours_.push_back(static_cast<double>(voxels.size()));
  const PclTiming pv = pcl_voxel_grid(cloud, c.voxel.leaf_m, c.voxel.min_points_per_voxel);
  voxel_pcl_.push_back(pv.ms);
  points_pcl_.push_back(static_cast<double>(pv.outputs));
  voxel_refused_ |= pv.refused;

  // Clustering input: our voxelized, ground-free cloud, for both.
  const PointCloud foreground = remove_ground(voxels, c.ground, sensor);
  t0 = Clock::now();
  const Segments segments = segment_cloud(foreground, c.segmenter);
  cluster_ours_.push_back(ms_since(t0));
  clusters_ours_.push_back(static_cast<double>(segments.size()));
  const PclTiming pc = pcl_euclidean_clusters(foreground, c.segmenter.cluster_distance_m, c.segmenter.min_points,
                                              c.segmenter.max_points);
  cluster_pcl_.push_back(pc.ms);
  clusters_pcl_.push_back(static_cast<double>(pc.outputs));

  // ESF on our segments. Degenerate ones (all-zero descriptor) are left out of both: PCL
  // would never return on them.
  std::vector<const PointCloud*> described;
  double ours = 0, ours_20k = 0;
  for (const Segment& s : segments) {
    t0 = Clock::now();
    const EsfDescriptor d = esf_descriptor(s.points, c.descriptors.esf_samples, c.descriptors.esf_seed);
    const double ms = ms_since(t0);
    if (std::none_of(d.begin(), d.end(), [](float v) { return v != 0.0f; })) continue;
    ours += ms;
    t0 = Clock::now();
    esf_descriptor(s.points, 20000, c.descriptors.esf_seed);
    ours_20k += ms_since(t0);
    described.push_back(&s.points);
  }
  const PclTiming pe = pcl_esf(described);
  esf_ours_.push_back(ours);
  esf_ours_20k_.push_back(ours_20k);
  esf_pcl_.push_back(pe.ms);
  esf_segments_.push_back(static_cast<double>(described.size()));
}

void StageComparison::print(const char* title, const SegmentationConfig& c) const {
  std::printf("\n%s: stock PCL stages vs ours on the same %zu query clouds (ms per cloud, median)\n", title,
              voxel_ours_.size());
  if (voxel_ours_.empty()) return;
  std::printf("  %-48s %9s %9s %9s   %s\n", "stage", "ours", "PCL", "PCL/ours", "output (median) ours / PCL");
  const auto row = [](const std::string& name, const std::vector<double>& ours, const std::vector<double>& pcl,
                      const std::string& output) {
    std::printf("  %-48s %9.1f %9.1f %9.2f   %s\n", name.c_str(), median(ours), median(pcl), median(pcl) / median(ours),
                output.c_str());
  };
  char name[128], out[128];
  std::snprintf(name, sizeof name, "VoxelGrid (leaf %.2f m, >= %d points)", c.voxel.leaf_m,
                c.voxel.min_points_per_voxel);
  std::snprintf(out, sizeof out, "%.0f / %.0f points%s", median(points_ours_), median(points_pcl_),
                voxel_refused_ ? " (PCL refused some: voxel index overflow)" : "");
  row(name, voxel_ours_, voxel_pcl_, out);
  std::snprintf(name, sizeof name, "EuclideanClusters (%.2f m, %d..%d points)", c.segmenter.cluster_distance_m,
                c.segmenter.min_points, c.segmenter.max_points);
  std::snprintf(out, sizeof out, "%.0f / %.0f segments (PCL time includes its kd-tree)", median(clusters_ours_),
                median(clusters_pcl_));
  row(name, cluster_ours_, cluster_pcl_, out);
  std::snprintf(name, sizeof name, "ESF, all segments (ours %d triples, PCL 20000)", c.descriptors.esf_samples);
  std::snprintf(out, sizeof out, "%.0f segments", median(esf_segments_));
  row(name, esf_ours_, esf_pcl_, out);
  row("ESF, all segments, both at 20000 triples", esf_ours_20k_, esf_pcl_, "same work per segment as PCL");
}

}  // namespace segmatch::bench
