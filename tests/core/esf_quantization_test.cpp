// core/esf_quantization.h: the error bound, exactness of the round trip from the integers on,
// and the edge cases (all zero, negative or NaN bins, a bin too large for the range).
#include <segmatch/core/description/esf_quantization.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace segmatch {
namespace {

EsfDescriptor dequantize(const QuantizedEsf& q) {
  EsfDescriptor out;
  for (int i = 0; i < kEsfBins; ++i) out[i] = dequantize_esf_bin(q.mantissas[i], esf_scale(q.exponent));
  return out;
}

TEST(EsfQuantization, ErrorIsBelowTwoToTheMinusSixteenOfTheLargestBinAndRoundTripsExactly) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    std::uniform_real_distribution<float> unit(0.f, 1.f);
    EsfDescriptor esf;
    float sum = 0.f, largest = 0.f;
    for (float& v : esf) sum += v = unit(rng) < 0.3f ? 0.f : std::pow(unit(rng), 4.f);
    for (float& v : esf) largest = std::max(largest, v /= sum);  // an ESF sums to 1
    const QuantizedEsf q = quantize_esf(esf, -64, 0);
    const EsfDescriptor back = dequantize(q);
    for (int i = 0; i < kEsfBins; ++i) {
      ASSERT_LE(std::abs(back[i] - esf[i]), largest * std::ldexp(1.f, -16)) << "bin " << i;
      if (esf[i] == 0.f) {
        ASSERT_EQ(back[i], 0.f);
      }
    }
    // The largest bin uses the top half of the range: the exponent is the smallest that holds it.
    EXPECT_GE(*std::max_element(q.mantissas.begin(), q.mantissas.end()), 32768);
    const QuantizedEsf again = quantize_esf(back, -64, 0);
    EXPECT_EQ(again.exponent, q.exponent);
    EXPECT_EQ(again.mantissas, q.mantissas) << "quantising a dequantised ESF gives the same integers";
  }
}

TEST(EsfQuantization, EdgeCases) {
  EsfDescriptor esf{};
  QuantizedEsf q = quantize_esf(esf, -64, 0);
  EXPECT_EQ(q.exponent, -64);
  for (uint16_t m : q.mantissas) EXPECT_EQ(m, 0);
  esf[0] = -1.f;
  esf[1] = std::numeric_limits<float>::quiet_NaN();
  esf[2] = 1.f;
  esf[3] = 1e6f;  // beyond 65535 * 2^0: saturates
  q = quantize_esf(esf, -64, 0);
  EXPECT_EQ(q.exponent, 0);
  EXPECT_EQ(q.mantissas[0], 0);
  EXPECT_EQ(q.mantissas[1], 0);
  EXPECT_EQ(q.mantissas[2], 1);
  EXPECT_EQ(q.mantissas[3], 65535);
}

}  // namespace
}  // namespace segmatch
