// Value types of the SegMatch pipeline (paper section III):
//   cloud -> segments -> descriptors -> candidate matches -> verified transform.
#pragma once

#include "segmatch/core/common/types.h"

#include <array>
#include <cstdint>
#include <vector>

namespace segmatch {

constexpr int kEigenFeatureCount = 7;  // Weinmann et al. 2014 (paper III-C)
constexpr int kEsfBins = 640;          // 10 histograms x 64 bins (Wohlkinger 2011)
constexpr int kEsfHistograms = 10;

using EigenFeatures = std::array<float, kEigenFeatureCount>;
using EsfDescriptor = std::array<float, kEsfBins>;

// One segment: the points of one object (ideally) in the frame of the cloud it was
// segmented from, with its descriptors once described.
struct Segment {
  uint64_t id = 0;
  PointCloud points;
  Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
  EigenFeatures eigen{};  // filled by describe_eigen()
  EsfDescriptor esf{};    // filled by describe_esf()
  bool has_eigen = false;
  bool has_esf = false;
  uint32_t label = 0;  // optional ground truth (SemanticKITTI majority label), 0 = unknown
};
using Segments = std::vector<Segment>;

// A candidate correspondence between a query segment and a target (map) segment.
struct Match {
  int query = -1;     // index into the query segments
  int target = -1;    // index into the target segments
  float score = 0.f;  // higher is more likely a true match (probability for the random forest)
};
using Matches = std::vector<Match>;

}  // namespace segmatch
