// Little-endian byte writer and bounds-checked reader shared by the codec. The reader never
// reads past its end: a short read sets a sticky failure and yields zeros.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace segmatch {
namespace api {
namespace wire {

class Writer {
 public:
  void u8(uint8_t v) { bytes_.push_back(v); }
  void u16(uint16_t v) { put(v, 2); }
  void u32(uint32_t v) { put(v, 4); }
  void u64(uint64_t v) { put(v, 8); }
  void f32(float v) {
    uint32_t b;
    std::memcpy(&b, &v, 4);
    u32(b);
  }
  void f64(double v) {
    uint64_t b;
    std::memcpy(&b, &v, 8);
    u64(b);
  }
  void str(const std::string& s) {
    u32(static_cast<uint32_t>(s.size()));
    bytes_.insert(bytes_.end(), s.begin(), s.end());
  }
  void raw(const uint8_t* data, size_t n) {
    if (n > 0) bytes_.insert(bytes_.end(), data, data + n);
  }
  // n floats at once (point clouds: millions of them, one resize instead of 4 push_backs each).
  void f32s(const float* v, size_t n) {
    const size_t at = bytes_.size();
    bytes_.resize(at + 4 * n);
    write_f32s(bytes_.data() + at, v, n);
  }
  void reserve(size_t n) { bytes_.reserve(n); }
  std::vector<uint8_t>& bytes() { return bytes_; }

  // Little-endian floats: the wire layout is the memory layout on little-endian hosts.
  static void write_f32s(uint8_t* out, const float* v, size_t n) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    std::memcpy(out, v, 4 * n);
#else
    for (size_t k = 0; k < n; ++k) {
      uint32_t b;
      std::memcpy(&b, &v[k], 4);
      for (int i = 0; i < 4; ++i) out[4 * k + i] = static_cast<uint8_t>(b >> (8 * i));
    }
#endif
  }

 private:
  void put(uint64_t v, int n) {
    const size_t at = bytes_.size();
    bytes_.resize(at + static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) bytes_[at + static_cast<size_t>(i)] = static_cast<uint8_t>(v >> (8 * i));
  }
  std::vector<uint8_t> bytes_;
};

class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  uint8_t u8() { return static_cast<uint8_t>(get(1)); }
  uint16_t u16() { return static_cast<uint16_t>(get(2)); }
  uint32_t u32() { return static_cast<uint32_t>(get(4)); }
  uint64_t u64() { return get(8); }
  float f32() {
    const uint32_t b = u32();
    float v;
    std::memcpy(&v, &b, 4);
    return v;
  }
  double f64() {
    const uint64_t b = u64();
    double v;
    std::memcpy(&v, &b, 8);
    return v;
  }
  // Length-prefixed string; fails (and sets too_long) when over max_bytes.
  std::string str(size_t max_bytes) {
    const uint32_t n = u32();
    if (failed_) return {};
    if (n > max_bytes) {
      too_long_ = failed_ = true;
      return {};
    }
    if (n > remaining()) {
      failed_ = true;
      return {};
    }
    std::string s(reinterpret_cast<const char*>(data_ + pos_), n);
    pos_ += n;
    return s;
  }
  size_t remaining() const { return size_ - pos_; }
  bool failed() const { return failed_; }
  bool too_long() const { return too_long_; }

  // n little-endian floats at once; false (and failed) if fewer bytes remain.
  bool f32s(float* out, size_t n) {
    if (failed_ || n > remaining() / 4) {
      failed_ = true;
      return false;
    }
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    std::memcpy(out, data_ + pos_, 4 * n);
    pos_ += 4 * n;
#else
    for (size_t k = 0; k < n; ++k) out[k] = f32();
#endif
    return true;
  }

 private:
  uint64_t get(size_t n) {
    if (failed_ || n > remaining()) {
      failed_ = true;
      return 0;
    }
    uint64_t v = 0;
    for (size_t i = 0; i < n; ++i) v |= static_cast<uint64_t>(data_[pos_ + i]) << (8 * i);
    pos_ += n;
    return v;
  }
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
  bool failed_ = false;
  bool too_long_ = false;
};

}  // namespace wire
}  // namespace api
}  // namespace segmatch
