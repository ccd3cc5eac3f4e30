// CDR reading and writing (cdr.h), and the ROS header every stamped message starts with.
#include "cdr.h"

#include <cstring>

namespace segmatch {
namespace io {
namespace detail {

namespace {

std::string hex_byte(uint8_t b) {
  const char* digits = "0123456789abcdef";
  return std::string("0x") + digits[b >> 4] + digits[b & 15];
}

}  // namespace

CdrReader::CdrReader(std::string_view cdr, const char* message) : cdr_(cdr), message_(message) {
  if (cdr.size() < 4) {
    throw IoError(std::string(message) + ": " + std::to_string(cdr.size()) +
                  " bytes, shorter than the 4-byte CDR encapsulation header");
  }
  const uint8_t kind = static_cast<uint8_t>(cdr[1]);
  if (cdr[0] != 0 || kind > 3) {
    throw IoError(std::string(message) + ": unknown CDR encapsulation " + hex_byte(static_cast<uint8_t>(cdr[0])) + " " +
                  hex_byte(kind) + " at offset 0 (plain CDR is 0x00 0x00 or 0x00 0x01)");
  }
  if (kind >= 2) {
    throw IoError(std::string(message) + ": encapsulation " + hex_byte(kind) + " is PL_CDR (" +
                  (kind == 3 ? "little" : "big") + "-endian parameter lists), not plain CDR: not supported");
  }
  swap_ = (kind == 0) != host_is_big_endian();
}

void CdrReader::fail(const char* field, const std::string& problem) const {
  throw IoError(std::string(message_) + "." + field + ": " + problem);
}

void CdrReader::need(size_t n, const char* field) const {
  const size_t left = cdr_.size() - pos_;
  if (n > left) {
    fail(field, std::to_string(n) + " bytes announced at offset " + std::to_string(pos_) + ", " + std::to_string(left) +
                    " left");
  }
}

void CdrReader::align(size_t size, const char* field) {
  const size_t rel = pos_ - 4;
  const size_t pad = (size - rel % size) % size;
  need(pad, field);
  pos_ += pad;
}

void CdrReader::load(void* out, size_t size, const char* field) {
  align(size, field);
  need(size, field);
  uint8_t* dst = static_cast<uint8_t*>(out);
  const char* src = cdr_.data() + pos_;
  for (size_t i = 0; i < size; ++i) dst[i] = static_cast<uint8_t>(src[swap_ ? size - 1 - i : i]);
  pos_ += size;
}

uint8_t CdrReader::u8(const char* field) {
  uint8_t v;
  load(&v, 1, field);
  return v;
}

uint32_t CdrReader::u32(const char* field) {
  uint32_t v;
  load(&v, 4, field);
  return v;
}

double CdrReader::f64(const char* field) {
  double v;
  load(&v, 8, field);
  return v;
}

std::string CdrReader::string(const char* field) {
  const uint32_t length = u32(field);
  std::string_view text = bytes(field, length);
  // The length counts a trailing NUL; some writers send 0 for an empty string.
  if (!text.empty() && text.back() == '\0') text.remove_suffix(1);
  return std::string(text);
}

uint32_t CdrReader::sequence_count(const char* field, size_t min_element_bytes) {
  const size_t at = pos_;
  const uint32_t count = u32(field);
  const size_t left = cdr_.size() - pos_;
  if (min_element_bytes > 0 && count > left / min_element_bytes) {
    fail(field, std::to_string(count) + " elements of at least " + std::to_string(min_element_bytes) +
                    " bytes announced at offset " + std::to_string(at) + ", " + std::to_string(left) + " bytes left");
  }
  return count;
}

std::string_view CdrReader::bytes(const char* field, size_t n) {
  need(n, field);
  const std::string_view out = cdr_.substr(pos_, n);
  pos_ += n;
  return out;
}

CdrWriter::CdrWriter() : out_(std::string("\x00\x01\x00\x00", 4)) {}

void CdrWriter::align(size_t size) {
  const size_t rel = out_.size() - 4;
  out_.append((size - rel % size) % size, '\0');
}

void CdrWriter::store(const void* in, size_t size) {
  align(size);
  const char* src = static_cast<const char*>(in);
  const bool swap = host_is_big_endian();
  for (size_t i = 0; i < size; ++i) out_.push_back(src[swap ? size - 1 - i : i]);
}

void CdrWriter::u8(uint8_t v) { store(&v, 1); }
void CdrWriter::u32(uint32_t v) { store(&v, 4); }
void CdrWriter::f64(double v) { store(&v, 8); }

void CdrWriter::string(std::string_view s) {
  u32(static_cast<uint32_t>(s.size() + 1));
  out_.append(s.data(), s.size());
  out_.push_back('\0');
}

RosHeader read_ros_header(CdrReader& in) {
  RosHeader header;
  header.stamp_sec = in.i32("header.stamp.sec");
  header.stamp_nanosec = in.u32("header.stamp.nanosec");
  header.frame_id = in.string("header.frame_id");
  return header;
}

void write_ros_header(CdrWriter& out, const RosHeader& header) {
  out.i32(header.stamp_sec);
  out.u32(header.stamp_nanosec);
  out.string(header.frame_id);
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
