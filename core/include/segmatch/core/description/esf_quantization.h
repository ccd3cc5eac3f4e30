// ESF histograms as 16-bit integers: u16 mantissas of one power-of-two scale 2^exponent per
// segment, the exponent the smallest in [min_exponent, max_exponent] that holds the largest bin.
// Rounding moves a bin by at most 2^-16 of the largest one. A power of two makes the round trip
// exact from the integers on (quantising a dequantised histogram gives the same integers), so
// re-encoding never drifts. LOCALIZE_SEGMENTS (docs/protocol.md 5.5) and map schema 3 both
// carry ESF this way; the demo and the real recordings localized identically with it (docs/how-defaults-were-chosen.md,
// "map size").
#pragma once

#include <segmatch/core/segmentation/segment.h>

#include <array>
#include <cstdint>

namespace segmatch {

struct QuantizedEsf {
  int exponent = 0;
  std::array<uint16_t, kEsfBins> mantissas{};
};

// Negative or NaN bins become 0; bins too large for 65535 * 2^max_exponent saturate.
QuantizedEsf quantize_esf(const EsfDescriptor& esf, int min_exponent, int max_exponent);

// mantissa * 2^exponent: exact in float for every u16 and exponent >= -100.
inline float dequantize_esf_bin(uint16_t mantissa, float scale) { return static_cast<float>(mantissa) * scale; }
float esf_scale(int exponent);

}  // namespace segmatch
