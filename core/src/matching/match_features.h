// Private helpers shared by the matchers (paper III-D pair feature vector).
#pragma once

#include "segmatch/core/segmentation/segment.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace segmatch {
namespace detail {

constexpr int kEsfBinsPerHistogram = kEsfBins / kEsfHistograms;

// A segment's ESF with each histogram scaled to sum 1 (an all-zero histogram stays zero), in
// `out` (kEsfBins floats). filter_matches() scales every involved segment once, so each of the
// ~200 pairs per query segment only takes minima and sums: the same floats as scaling inside
// the intersection (a[i] * s is the same product wherever it is computed).
inline void scale_esf(const EsfDescriptor& esf, float* out) {
  for (int h = 0; h < kEsfHistograms; ++h) {
    const float* a = esf.data() + h * kEsfBinsPerHistogram;
    float sum = 0.f;
    for (int b = 0; b < kEsfBinsPerHistogram; ++b) sum += a[b];
    const float scale = sum > 0.f ? 1.f / sum : 0.f;
    for (int b = 0; b < kEsfBinsPerHistogram; ++b) out[h * kEsfBinsPerHistogram + b] = a[b] * scale;
  }
}

// Writes the 21 eigen values, then (if both scaled ESFs of scale_esf() are given) the 10
// histogram intersections. `out` must hold 21 or 31 floats.
inline void write_pair_features(const EigenFeatures& fq, const EigenFeatures& ft, const float* esf_q,
                                const float* esf_t, float* out) {
  for (int d = 0; d < kEigenFeatureCount; ++d) {
    out[d] = std::abs(fq[d] - ft[d]);
    out[kEigenFeatureCount + d] = fq[d];
    out[2 * kEigenFeatureCount + d] = ft[d];
  }
  if (esf_q == nullptr || esf_t == nullptr) return;
  constexpr int bins = kEsfBinsPerHistogram;
  static_assert(bins % 8 == 0, "ESF histogram size");
  float* shapes = out + 3 * kEigenFeatureCount;
  for (int h = 0; h < kEsfHistograms; ++h) {
    const float* a = esf_q + h * bins;
    const float* b = esf_t + h * bins;
    // 8 independent partial sums so the compiler can vectorise (bins is a multiple of 8).
    float acc[8] = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
    for (int i = 0; i < bins; i += 8)
      for (int l = 0; l < 8; ++l) acc[l] += std::min(a[i + l], b[i + l]);
    shapes[h] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

}  // namespace detail
}  // namespace segmatch
