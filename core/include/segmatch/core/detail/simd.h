// Four float lanes: the one home of SIMD in the project. The kernels that use it (Euclidean
// clustering's distance masks, refinement's nearest neighbour, the simulator's ray-box tests)
// are written once against these functions. With SEGMATCH_SIMD on (CMake option, default ON)
// and SSE2 available (every x86-64), they are SSE2 intrinsics; otherwise (-DSEGMATCH_SIMD=OFF,
// or a CPU without SSE2 such as the ARM computers vehicles carry) plain loops over four floats.
//
// Both give the same bits: every function follows the SSE2 instruction's exact semantics
// (min(a, b) = a < b ? a : b, NaN compares false, the mask is a lane's sign of the comparison),
// the lanes do the same IEEE single-precision operations in the same order, and the core is
// compiled with -ffp-contract=off so that no compiler fuses a multiply and an add on a CPU
// with FMA. tests/core/simd_test.cpp checks the two against each other.
#pragma once

#include <cstddef>
#include <cstdint>

#if !defined(SEGMATCH_SIMD)
#define SEGMATCH_SIMD 1
#endif
#if SEGMATCH_SIMD && (defined(__SSE2__) || defined(_M_X64))
#define SEGMATCH_SIMD_SSE2 1
#include <emmintrin.h>
#else
#define SEGMATCH_SIMD_SSE2 0
#endif

namespace segmatch::simd {

// The scalar model of one lane: what each SSE2 instruction does to it.
namespace lane {
inline float min(float a, float b) { return a < b ? a : b; }  // minps: the second if unordered
inline float max(float a, float b) { return a > b ? a : b; }
}  // namespace lane

#if SEGMATCH_SIMD_SSE2
struct F4 {
  __m128 v;
};
struct I4 {
  __m128i v;
};
inline const char* backend() { return "sse2"; }
inline F4 load(const float* p) { return {_mm_loadu_ps(p)}; }
inline F4 splat(float x) { return {_mm_set1_ps(x)}; }
inline F4 make(float l0, float l1, float l2, float l3) { return {_mm_setr_ps(l0, l1, l2, l3)}; }
inline F4 zero() { return {_mm_setzero_ps()}; }
inline F4 operator+(F4 a, F4 b) { return {_mm_add_ps(a.v, b.v)}; }
inline F4 operator-(F4 a, F4 b) { return {_mm_sub_ps(a.v, b.v)}; }
inline F4 operator*(F4 a, F4 b) { return {_mm_mul_ps(a.v, b.v)}; }
inline F4 min(F4 a, F4 b) { return {_mm_min_ps(a.v, b.v)}; }
inline F4 max(F4 a, F4 b) { return {_mm_max_ps(a.v, b.v)}; }
// Bit k set where lane k of a <= b (of a < b).
inline int le_bits(F4 a, F4 b) { return _mm_movemask_ps(_mm_cmple_ps(a.v, b.v)); }
inline int lt_bits(F4 a, F4 b) { return _mm_movemask_ps(_mm_cmplt_ps(a.v, b.v)); }
inline void store(float* p, F4 a) { _mm_storeu_ps(p, a.v); }
inline I4 make(int32_t l0, int32_t l1, int32_t l2, int32_t l3) { return {_mm_setr_epi32(l0, l1, l2, l3)}; }
inline I4 splat(int32_t x) { return {_mm_set1_epi32(x)}; }
inline I4 operator+(I4 a, I4 b) { return {_mm_add_epi32(a.v, b.v)}; }
// Lane k of if_lt where lane k of a < b, else of otherwise.
inline I4 select_lt(F4 a, F4 b, I4 if_lt, I4 otherwise) {
  const __m128i m = _mm_castps_si128(_mm_cmplt_ps(a.v, b.v));
  return {_mm_or_si128(_mm_and_si128(m, if_lt.v), _mm_andnot_si128(m, otherwise.v))};
}
inline void store(int32_t* p, I4 a) { _mm_storeu_si128(reinterpret_cast<__m128i*>(p), a.v); }
#else
struct F4 {
  float v[4];
};
struct I4 {
  int32_t v[4];
};
inline const char* backend() { return "scalar"; }
template <typename Op>
inline F4 each(F4 a, F4 b, Op op) {
  return {{op(a.v[0], b.v[0]), op(a.v[1], b.v[1]), op(a.v[2], b.v[2]), op(a.v[3], b.v[3])}};
}
inline F4 load(const float* p) { return {{p[0], p[1], p[2], p[3]}}; }
inline F4 splat(float x) { return {{x, x, x, x}}; }
inline F4 make(float l0, float l1, float l2, float l3) { return {{l0, l1, l2, l3}}; }
inline F4 zero() { return splat(0.0f); }
inline F4 operator+(F4 a, F4 b) {
  return each(a, b, [](float x, float y) { return x + y; });
}
inline F4 operator-(F4 a, F4 b) {
  return each(a, b, [](float x, float y) { return x - y; });
}
inline F4 operator*(F4 a, F4 b) {
  return each(a, b, [](float x, float y) { return x * y; });
}
inline F4 min(F4 a, F4 b) { return each(a, b, lane::min); }
inline F4 max(F4 a, F4 b) { return each(a, b, lane::max); }
inline int le_bits(F4 a, F4 b) {
  return (a.v[0] <= b.v[0]) | (a.v[1] <= b.v[1]) << 1 | (a.v[2] <= b.v[2]) << 2 | (a.v[3] <= b.v[3]) << 3;
}
inline int lt_bits(F4 a, F4 b) {
  return (a.v[0] < b.v[0]) | (a.v[1] < b.v[1]) << 1 | (a.v[2] < b.v[2]) << 2 | (a.v[3] < b.v[3]) << 3;
}
inline void store(float* p, F4 a) {
  for (int k = 0; k < 4; ++k) p[k] = a.v[k];
}
inline I4 make(int32_t l0, int32_t l1, int32_t l2, int32_t l3) { return {{l0, l1, l2, l3}}; }
inline I4 splat(int32_t x) { return {{x, x, x, x}}; }
inline I4 operator+(I4 a, I4 b) { return {{a.v[0] + b.v[0], a.v[1] + b.v[1], a.v[2] + b.v[2], a.v[3] + b.v[3]}}; }
inline I4 select_lt(F4 a, F4 b, I4 if_lt, I4 otherwise) {
  I4 out;
  for (int k = 0; k < 4; ++k) out.v[k] = a.v[k] < b.v[k] ? if_lt.v[k] : otherwise.v[k];
  return out;
}
inline void store(int32_t* p, I4 a) {
  for (int k = 0; k < 4; ++k) p[k] = a.v[k];
}
#endif

// Lane k of a (a store and a load: for the few places that leave the lanes).
inline float get(F4 a, int k) {
  float out[4];
  store(out, a);
  return out[k];
}

// sum a[i] * b[i] over n floats: four accumulators of four lanes over blocks of 16 (independent
// adds keep the pipeline full), then blocks of 4 into the first; the 16 lanes added in a fixed
// order, then the rest in order. The same bits on both backends.
inline float dot(const float* a, const float* b, std::size_t n) {
  F4 acc0 = zero(), acc1 = zero(), acc2 = zero(), acc3 = zero();
  std::size_t i = 0;
  for (; i + 16 <= n; i += 16) {
    acc0 = acc0 + load(a + i) * load(b + i);
    acc1 = acc1 + load(a + i + 4) * load(b + i + 4);
    acc2 = acc2 + load(a + i + 8) * load(b + i + 8);
    acc3 = acc3 + load(a + i + 12) * load(b + i + 12);
  }
  for (; i + 4 <= n; i += 4) acc0 = acc0 + load(a + i) * load(b + i);
  float lanes[4];
  store(lanes, (acc0 + acc1) + (acc2 + acc3));
  float sum = ((lanes[0] + lanes[1]) + lanes[2]) + lanes[3];
  for (; i < n; ++i) sum += a[i] * b[i];
  return sum;
}

}  // namespace segmatch::simd
