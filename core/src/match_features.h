// Private helpers shared by the matchers (paper III-D pair feature vector).
#pragma once

#include "segmatch/core/segment.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace segmatch {
namespace detail {

constexpr int kEsfBinsPerHistogram = kEsfBins / kEsfHistograms;

// A segment's ESF with, per histogram, the factor that scales it to sum 1 (0 for an all-zero
// histogram). Scaling on the fly inside the intersection gives the same floats as scaling a
// copy first, without writing 2.5 KB per segment per query.
struct ScaledEsf {
  const EsfDescriptor* esf = nullptr;
  std::array<float, kEsfHistograms> scale{};
};

inline ScaledEsf scaled_esf(const EsfDescriptor& esf) {
  ScaledEsf out;
  out.esf = &esf;
  for (int h = 0; h < kEsfHistograms; ++h) {
    float sum = 0.f;
    for (int b = 0; b < kEsfBinsPerHistogram; ++b) sum += esf[h * kEsfBinsPerHistogram + b];
    out.scale[h] = sum > 0.f ? 1.f / sum : 0.f;
  }
  return out;
}

// Writes the 21 eigen values, then (if both ESFs are given) the 10 intersections of the
// histograms scaled to sum 1. `out` must hold 21 or 31 floats.
inline void write_pair_features(const EigenFeatures& fq, const EigenFeatures& ft,
                                const ScaledEsf* esf_q, const ScaledEsf* esf_t, float* out) {
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
    const float* a = esf_q->esf->data() + h * bins;
    const float* b = esf_t->esf->data() + h * bins;
    const float sa = esf_q->scale[h], sb = esf_t->scale[h];
    // 8 independent partial sums so the compiler can vectorise (bins is a multiple of 8).
    float acc[8] = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};
    for (int i = 0; i < bins; i += 8)
      for (int l = 0; l < 8; ++l) acc[l] += std::min(a[i + l] * sa, b[i + l] * sb);
    shapes[h] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

}  // namespace detail
}  // namespace segmatch
