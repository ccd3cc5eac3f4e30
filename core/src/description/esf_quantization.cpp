#include "segmatch/core/description/esf_quantization.h"

#include <algorithm>
#include <cmath>

namespace segmatch {

namespace {
constexpr double kU16Max = 65535.0;
}  // namespace

float esf_scale(int exponent) { return static_cast<float>(std::ldexp(1.0, exponent)); }

QuantizedEsf quantize_esf(const EsfDescriptor& esf, int min_exponent, int max_exponent) {
  float max_bin = 0.f;
  for (float v : esf) max_bin = std::max(max_bin, v);
  QuantizedEsf q;
  q.exponent = min_exponent;
  while (q.exponent < max_exponent && max_bin > kU16Max * std::ldexp(1.0, q.exponent)) ++q.exponent;
  const double inverse = std::ldexp(1.0, -q.exponent);
  for (int i = 0; i < kEsfBins; ++i)
    q.mantissas[i] = static_cast<uint16_t>(std::clamp(std::nearbyint(std::max(0.f, esf[i]) * inverse), 0.0, kU16Max));
  return q;
}

}  // namespace segmatch
