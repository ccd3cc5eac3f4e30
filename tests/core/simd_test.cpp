// segmatch/core/detail/simd.h: every four-lane operation against the scalar model of one lane (the
// SSE2 instruction's semantics), bit for bit, on ordinary values and on the ones where
// implementations differ: NaN, infinities, signed zeros, denormals. Run in the SSE2 build it
// checks the intrinsics; in a -DSEGMATCH_SIMD=OFF build, the scalar lanes.
#include "segmatch/core/detail/simd.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace segmatch {
namespace {

uint32_t bits(float x) {
  uint32_t b;
  std::memcpy(&b, &x, sizeof b);
  return b;
}

std::vector<float> values() {
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<float> v = {0.f, -0.f, 1.f, -1.f, 0.2f, 0.04f, inf, -inf, nan, 1e-40f, -1e-40f, 3.4e38f, 1e6f, -1e6f};
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-100.f, 100.f);
  for (int k = 0; k < 200; ++k) v.push_back(u(rng));
  return v;
}

using Scalar = float (*)(float, float);
using Lanes = simd::F4 (*)(simd::F4, simd::F4);

void expect_lanes(Lanes f4, Scalar f, const char* name) {
  const std::vector<float> v = values();
  for (size_t i = 0; i + 4 <= v.size(); ++i)
    for (size_t j = 0; j + 4 <= v.size(); j += 3) {
      float out[4];
      simd::store(out, f4(simd::load(&v[i]), simd::load(&v[j])));
      for (int k = 0; k < 4; ++k) {
        const float expected = f(v[i + k], v[j + k]);
        if (std::isnan(expected)) {
          EXPECT_TRUE(std::isnan(out[k])) << name << "(" << v[i + k] << ", " << v[j + k] << ")";
          continue;
        }
        ASSERT_EQ(bits(out[k]), bits(expected)) << name << "(" << v[i + k] << ", " << v[j + k] << ") lane " << k;
      }
    }
}

TEST(Simd, ArithmeticMinAndMaxFollowTheLaneModel) {
  std::printf("[simd] backend: %s\n", simd::backend());
  expect_lanes([](simd::F4 a, simd::F4 b) { return a + b; }, [](float a, float b) { return a + b; }, "add");
  expect_lanes([](simd::F4 a, simd::F4 b) { return a - b; }, [](float a, float b) { return a - b; }, "sub");
  expect_lanes([](simd::F4 a, simd::F4 b) { return a * b; }, [](float a, float b) { return a * b; }, "mul");
  expect_lanes(simd::min, simd::lane::min, "min");
  expect_lanes(simd::max, simd::lane::max, "max");
}

TEST(Simd, ComparisonMasksAndSelect) {
  const std::vector<float> v = values();
  for (size_t i = 0; i + 4 <= v.size(); ++i)
    for (size_t j = 0; j + 4 <= v.size(); j += 5) {
      const simd::F4 a = simd::load(&v[i]), b = simd::load(&v[j]);
      int le = 0, lt = 0;
      for (int k = 0; k < 4; ++k) le |= (v[i + k] <= v[j + k]) << k, lt |= (v[i + k] < v[j + k]) << k;
      ASSERT_EQ(simd::le_bits(a, b), le) << i << " " << j;
      ASSERT_EQ(simd::lt_bits(a, b), lt) << i << " " << j;
      int32_t picked[4];
      simd::store(picked,
                  simd::select_lt(a, b, simd::make(1, 2, 3, 4), simd::splat(int32_t(-7)) + simd::splat(int32_t(1))));
      for (int k = 0; k < 4; ++k) ASSERT_EQ(picked[k], v[i + k] < v[j + k] ? k + 1 : -6);
    }
}

// simd::dot's stated order, written out lane by lane: four accumulators over blocks of 16, blocks
// of 4 into the first, the lanes added in order, then the tail.
float dot_in_stated_order(const float* a, const float* b, size_t n) {
  float acc[4][4] = {};
  size_t i = 0;
  for (; i + 16 <= n; i += 16)
    for (int q = 0; q < 4; ++q)
      for (int l = 0; l < 4; ++l) acc[q][l] = acc[q][l] + a[i + 4 * q + l] * b[i + 4 * q + l];
  for (; i + 4 <= n; i += 4)
    for (int l = 0; l < 4; ++l) acc[0][l] = acc[0][l] + a[i + l] * b[i + l];
  float lanes[4];
  for (int l = 0; l < 4; ++l) lanes[l] = (acc[0][l] + acc[1][l]) + (acc[2][l] + acc[3][l]);
  float sum = ((lanes[0] + lanes[1]) + lanes[2]) + lanes[3];
  for (; i < n; ++i) sum += a[i] * b[i];
  return sum;
}

TEST(Simd, DotFollowsItsStatedOrderAndIsADotProduct) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-2.f, 2.f);
  for (size_t n : {0, 1, 3, 4, 5, 15, 16, 17, 31, 33, 64, 100, 1200}) {
    std::vector<float> a(n), b(n);
    for (size_t i = 0; i < n; ++i) a[i] = u(rng), b[i] = u(rng);
    const float got = simd::dot(a.data(), b.data(), n);
    EXPECT_EQ(bits(got), bits(dot_in_stated_order(a.data(), b.data(), n))) << "n " << n;
    double exact = 0.0;
    for (size_t i = 0; i < n; ++i) exact += double(a[i]) * b[i];
    EXPECT_NEAR(got, exact, 1e-4 * (1.0 + std::sqrt(double(n)))) << "n " << n;
  }
}

TEST(Simd, MakeSplatZeroAndGet) {
  const simd::F4 m = simd::make(1.f, -2.f, 3.5f, -0.f);
  EXPECT_EQ(simd::get(m, 0), 1.f);
  EXPECT_EQ(simd::get(m, 1), -2.f);
  EXPECT_EQ(simd::get(m, 2), 3.5f);
  EXPECT_EQ(bits(simd::get(m, 3)), bits(-0.f));
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(simd::get(simd::splat(0.25f), k), 0.25f);
    EXPECT_EQ(bits(simd::get(simd::zero(), k)), 0u);
  }
}

}  // namespace
}  // namespace segmatch
