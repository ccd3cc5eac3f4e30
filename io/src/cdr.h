// Internal: OMG CDR (plain, version 1) as ROS 2 serialises messages. A 4-byte encapsulation
// header (00 01 = little-endian, 00 00 = big-endian) precedes the fields; every primitive is
// aligned to its own size counted from the end of that header; strings are a uint32 length
// that includes the trailing NUL, then the bytes; sequences a uint32 count, then the elements.
//
// The reader never trusts a length: every read checks the bytes left and throws IoError
// "<Message>.<field>: N bytes announced at offset K, M left", where offsets count from the
// first byte of the message (its encapsulation header included), as a hex dump shows them.
#pragma once

#include <segmatch/io/bag.h>
#include <segmatch/io/error.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>

namespace segmatch {
namespace io {
namespace detail {

// The byte order of this machine: every target so far is little-endian, but the swaps below do
// not rely on it.
inline bool host_is_big_endian() {
  const uint16_t probe = 1;
  uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

class CdrReader {
 public:
  // message: the type's short name for error messages ("PointCloud2"). Throws IoError for a
  // payload shorter than the header or an encapsulation other than plain CDR.
  CdrReader(std::string_view cdr, const char* message);

  uint8_t u8(const char* field);
  bool boolean(const char* field) { return u8(field) != 0; }
  uint32_t u32(const char* field);
  int32_t i32(const char* field) { return static_cast<int32_t>(u32(field)); }
  double f64(const char* field);
  std::string string(const char* field);
  // A sequence's element count, checked against the bytes left: each element takes at least
  // min_element_bytes, so a forged count cannot make the caller reserve more than the payload.
  uint32_t sequence_count(const char* field, size_t min_element_bytes);
  // n raw bytes (a uint8[] sequence's body), without copying.
  std::string_view bytes(const char* field, size_t n);

  size_t offset() const { return pos_; }  // from the start of the message
  [[noreturn]] void fail(const char* field, const std::string& problem) const;

 private:
  void align(size_t size, const char* field);
  void need(size_t n, const char* field) const;
  void load(void* out, size_t size, const char* field);

  std::string_view cdr_;
  const char* message_;
  size_t pos_ = 4;
  bool swap_ = false;  // the payload's byte order differs from ours
};

// Little-endian CDR with the header 00 01 00 00, as ROS 2 publishes on x86 and ARM.
class CdrWriter {
 public:
  CdrWriter();
  void u8(uint8_t v);
  void boolean(bool v) { u8(v ? 1 : 0); }
  void u32(uint32_t v);
  void i32(int32_t v) { u32(static_cast<uint32_t>(v)); }
  void f64(double v);
  void string(std::string_view s);
  void bytes(std::string_view b) { out_.append(b.data(), b.size()); }
  std::string take() { return std::move(out_); }

 private:
  void align(size_t size);
  void store(const void* in, size_t size);
  std::string out_;
};

// std_msgs/msg/Header {builtin_interfaces/Time stamp, string frame_id}; errors name the
// fields header.stamp.sec, header.stamp.nanosec and header.frame_id.
RosHeader read_ros_header(CdrReader& in);
void write_ros_header(CdrWriter& out, const RosHeader& header);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
