// Segment descriptors (SegMatch, Dube et al. ICRA 2017, section III-C "Feature extraction"):
// the paper describes every segment with
//   * eigenvalue-based features (Weinmann et al. 2014), 7 floats, and
//   * the Ensemble of Shape Functions (Wohlkinger & Vincze 2011), 640 floats,
// which the matcher (section III-D) compares. Everything here is deterministic: the ESF point
// triples are drawn from segmatch::Rng seeded by the caller, never from rand() or the clock.
#pragma once

#include "segmatch/core/common/deadline.h"
#include "segmatch/core/common/types.h"
#include "segmatch/core/segmentation/segment.h"

#include <cstdint>

namespace segmatch {

struct DescriptorConfig {
  // Compute the 7 eigenvalue features (a few microseconds per segment).
  bool compute_eigen = true;
  // Compute the 640-bin ESF histogram (the expensive descriptor).
  bool compute_esf = true;
  // Point triples sampled per segment for ESF; cost is linear in it (~0.3-0.6 us per triple
  // on the shared dev VM, mostly the 3 voxel line walks). PCL's pcl::ESFEstimation
  // hard-codes 20000 (~12 ms per segment here). Histogram intersection with a 20000-triple
  // descriptor of the same segment (two independent 20000-triple runs agree at ~0.97):
  //   500: ~0.85-0.91   1000: ~0.89-0.93   2000: ~0.92-0.95   4000: ~0.94-0.97.
  // 1000 keeps a 1000-point segment at ~0.5-0.7 ms; lower it if the query budget demands.
  // Must be > 0.
  int esf_samples = 1000;
  // Seed of the ESF triple sampling. The same seed and the same points give bitwise the same
  // descriptor, whatever the segment's position in a vector or the calling thread.
  uint64_t esf_seed = 0x5E6Du;

  // Throws std::invalid_argument naming the offending field.
  void validate() const;
};

// Weinmann et al. 2014 eigenvalue features of the 3x3 covariance of `points`. Eigenvalues are
// normalised to sum 1 and sorted l1 >= l2 >= l3. Order of the output:
//   [0] linearity (l1-l2)/l1      [1] planarity (l2-l3)/l1     [2] scattering l3/l1
//   [3] omnivariance cbrt(l1 l2 l3)  [4] anisotropy (l1-l3)/l1
//   [5] eigenentropy -sum li ln li (0 ln 0 = 0)   [6] change of curvature l3/(l1+l2+l3)
// Degenerate input (< 3 points, or all points identical) returns all zeros; never NaN.
EigenFeatures eigen_features(const PointCloud& points);

// Ensemble of Shape Functions (Wohlkinger & Vincze 2011), same layout and normalisation as
// PCL's pcl::ESFEstimation (so the output is comparable to PCL's), 10 histograms x 64 bins:
//   [  0, 64) A3 in     [ 64,128) A3 out     [128,192) A3 mixed
//   [192,256) D3 in     [256,320) D3 out     [320,384) D3 mixed
//   [384,448) D2 in     [448,512) D2 out     [512,576) D2 mixed   [576,640) D2 in-ratio
// The segment is centred and scaled into a 64^3 voxel grid; in/out/mixed is decided by the
// voxel line walk between the sampled points. PCL's per-histogram weights are applied and the
// whole 640-vector sums to 1 (PCL normalises the concatenation, not each histogram).
// `samples` triples (> 0, else std::invalid_argument) are drawn from Rng(seed).
// Fewer than 3 points, or no non-degenerate triangle found (e.g. perfectly collinear points,
// where PCL would loop forever), returns all zeros.
EsfDescriptor esf_descriptor(const PointCloud& points, int samples, uint64_t seed);

// Fills eigen / esf and has_eigen / has_esf of every segment as enabled in `config` (a flag
// set means "computed"; degenerate segments get all-zero descriptors). A zero centroid of a
// non-empty segment is recomputed as the mean of its points. Every segment uses
// config.esf_seed, so a segment's descriptors depend only on its points. Validates `config`.
// Once `deadline` has passed, the remaining segments are left undescribed (the caller sees
// deadline.passed() and drops the result).
void describe_segments(Segments& segments, const DescriptorConfig& config, const Deadline& deadline = {});

}  // namespace segmatch
