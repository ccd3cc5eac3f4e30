// Internal: typed scalars as they appear in binary PCD and PLY records, and the builder that
// turns decoded values into a CloudData (dropping non-finite points with their labels).
#pragma once

#include <segmatch/io/cloud_io.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>

namespace segmatch {
namespace io {
namespace detail {

enum class ScalarKind { kFloat, kUnsigned, kSigned };

struct ScalarType {
  ScalarKind kind = ScalarKind::kFloat;
  int size = 4;  // bytes: 1, 2, 4 or 8 (floats: 4 or 8)
};

inline bool is_valid(ScalarType t) {
  if (t.kind == ScalarKind::kFloat) return t.size == 4 || t.size == 8;
  return t.size == 1 || t.size == 2 || t.size == 4 || t.size == 8;
}

// Copies `size` bytes, reversing them when the file's byte order differs from ours. The
// constant-size memcpy calls compile to single loads (a variable-size one is a libc call).
inline void load_bytes(const uint8_t* src, int size, bool swap, uint8_t* dst) {
  if (swap) {
    for (int i = 0; i < size; ++i) dst[i] = src[size - 1 - i];
    return;
  }
  switch (size) {
    case 1: std::memcpy(dst, src, 1); break;
    case 2: std::memcpy(dst, src, 2); break;
    case 4: std::memcpy(dst, src, 4); break;
    default: std::memcpy(dst, src, 8); break;
  }
}

// Reinterprets sizeof(U) bytes as U (unsigned) or S (its signed twin), widened to 64 bits.
template <typename U, typename S>
int64_t widen(const uint8_t* bytes, bool is_signed) {
  U u;
  std::memcpy(&u, bytes, sizeof(U));
  return is_signed ? static_cast<int64_t>(static_cast<S>(u)) : static_cast<int64_t>(u);
}

// Integer value of an integer scalar, widened to 64 bits (sign-extended for signed types).
// A U8 above 2^63 wraps; no point-cloud field needs that range.
inline int64_t load_integer(const uint8_t* src, ScalarType t, bool swap) {
  uint8_t b[8] = {};
  load_bytes(src, t.size, swap, b);
  const bool is_signed = t.kind == ScalarKind::kSigned;
  switch (t.size) {
    case 1: return widen<uint8_t, int8_t>(b, is_signed);
    case 2: return widen<uint16_t, int16_t>(b, is_signed);
    case 4: return widen<uint32_t, int32_t>(b, is_signed);
    default: return widen<uint64_t, int64_t>(b, is_signed);
  }
}

inline double load_double(const uint8_t* src, ScalarType t, bool swap) {
  if (t.kind == ScalarKind::kFloat && t.size == 4 && !swap) {  // the common case: F4 fields
    float f;
    std::memcpy(&f, src, 4);
    return f;
  }
  if (t.kind != ScalarKind::kFloat) return static_cast<double>(load_integer(src, t, swap));
  uint8_t b[8] = {};
  load_bytes(src, t.size, swap, b);
  if (t.size == 4) {
    float f;
    std::memcpy(&f, b, 4);
    return f;
  }
  double d;
  std::memcpy(&d, b, 8);
  return d;
}

// double -> float without undefined behaviour: values beyond float range become Inf (and
// the point is then dropped as non-finite).
inline float to_float(double v) {
  if (std::isnan(v)) return std::numeric_limits<float>::quiet_NaN();
  if (v > std::numeric_limits<float>::max()) return std::numeric_limits<float>::infinity();
  if (v < -std::numeric_limits<float>::max()) return -std::numeric_limits<float>::infinity();
  return static_cast<float>(v);
}

// A label from a float field must be a whole number in uint32 range; integer fields keep
// their low 32 bits (so an I4 -1 reads as 0xFFFFFFFF, as PCL would).
inline bool to_label(double v, ScalarType t, uint32_t* label) {
  if (t.kind != ScalarKind::kFloat) {
    // An ascii body may hold any number in an integer field; beyond int64 the cast is undefined
    // (found by fuzzing: 9.2e18 in a U field).
    if (!(v >= -9223372036854775808.0 && v < 9223372036854775808.0)) return false;
    *label = static_cast<uint32_t>(static_cast<int64_t>(v));
    return true;
  }
  if (!(v >= 0.0 && v <= 4294967295.0)) return false;
  *label = static_cast<uint32_t>(v);
  return true;
}

// Collects decoded points, dropping those with a non-finite coordinate (and their labels),
// so every reader applies the same policy.
class CloudBuilder {
 public:
  CloudBuilder(size_t expected_points, bool has_intensity, bool has_labels) : has_labels_(has_labels) {
    data_.has_intensity = has_intensity;
    data_.points.reserve(expected_points);
    if (has_labels) data_.labels.reserve(expected_points);
  }

  void add(float x, float y, float z, float intensity, uint32_t label) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      ++data_.dropped_non_finite;
      return;
    }
    Point p;
    p.x = x;
    p.y = y;
    p.z = z;
    p.intensity = std::isfinite(intensity) ? intensity : 0.0f;
    data_.points.push_back(p);
    if (has_labels_) data_.labels.push_back(label);
  }

  CloudData finish() { return std::move(data_); }

 private:
  bool has_labels_;
  CloudData data_;
};

}  // namespace detail
}  // namespace io
}  // namespace segmatch
