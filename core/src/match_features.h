// Private helpers shared by the matchers (paper III-D pair feature vector).
#pragma once

#include "segmatch/core/segment.h"

#include <algorithm>
#include <cmath>

namespace segmatch {
namespace detail {

// Each of the 10 ESF histograms scaled to sum 1 (an all-zero histogram stays zero).
inline EsfDescriptor normalise_esf(const EsfDescriptor& esf) {
  EsfDescriptor out;
  constexpr int bins = kEsfBins / kEsfHistograms;
  for (int h = 0; h < kEsfHistograms; ++h) {
    float sum = 0.f;
    for (int b = 0; b < bins; ++b) sum += esf[h * bins + b];
    const float inv = sum > 0.f ? 1.f / sum : 0.f;
    for (int b = 0; b < bins; ++b) out[h * bins + b] = esf[h * bins + b] * inv;
  }
  return out;
}

// Writes the 21 eigen values, then (if both ESF pointers are given) the 10 intersections of
// the already normalised histograms. `out` must hold 21 or 31 floats.
inline void write_pair_features(const EigenFeatures& fq, const EigenFeatures& ft,
                                const EsfDescriptor* esf_q, const EsfDescriptor* esf_t,
                                float* out) {
  for (int d = 0; d < kEigenFeatureCount; ++d) {
    out[d] = std::abs(fq[d] - ft[d]);
    out[kEigenFeatureCount + d] = fq[d];
    out[2 * kEigenFeatureCount + d] = ft[d];
  }
  if (esf_q == nullptr || esf_t == nullptr) return;
  constexpr int bins = kEsfBins / kEsfHistograms;
  static_assert(bins % 8 == 0, "ESF histogram size");
  float* shapes = out + 3 * kEigenFeatureCount;
  for (int h = 0; h < kEsfHistograms; ++h) {
    const float* a = esf_q->data() + h * bins;
    const float* b = esf_t->data() + h * bins;
    // 8 independent partial sums so the compiler can vectorise (bins is a multiple of 8).
    float acc[8] = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
    for (int i = 0; i < bins; i += 8)
      for (int l = 0; l < 8; ++l) acc[l] += std::min(a[i + l], b[i + l]);
    shapes[h] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

}  // namespace detail
}  // namespace segmatch
