// Private: the segmenter implementations behind segment_cloud(). Each returns clusters as
// lists of point indices; segment_cloud() filters them by size and builds Segments.
#pragma once

#include <cstdint>
#include <vector>

#include "segmatch/core/segmentation/segmenter.h"

namespace segmatch {
namespace detail {

using Clusters = std::vector<std::vector<uint32_t>>;

// Euclidean clustering: connected components of "closer than cluster_distance_m".
Clusters euclidean_clusters(const PointCloud& cloud, const SegmenterConfig& config);

// Region growing with smoothness constraint (Rabbani et al. 2006).
Clusters region_growing_clusters(const PointCloud& cloud, const SegmenterConfig& config);

// order[k] is the input index of item k, root[k] < order.size() its group. Returns the
// groups of [min_points, max_points] items as sorted input indices, ordered by their
// smallest index (so segment ids are deterministic).
Clusters collect_clusters(const std::vector<uint32_t>& order, std::vector<uint32_t> root,
                          const SegmenterConfig& config);

// Segment s holds the points of clusters[s] (input order), their centroid and, with labels,
// their majority label; ids 0..n-1.
Segments build_segments(const PointCloud& cloud, const Clusters& clusters, const std::vector<uint32_t>* labels);

}  // namespace detail
}  // namespace segmatch
