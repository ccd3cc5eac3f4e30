// LZF stream format (liblzf): a sequence of chunks, each starting with a control byte c.
//   c < 32:   literal run, the next c + 1 bytes are copied as-is.
//   c >= 32:  back reference, len = c >> 5 (7 => add the next byte), offset high bits c & 31,
//             then one byte of offset low bits; copies len + 2 bytes starting
//             offset + 1 bytes back in the output (the source may overlap the destination).
#include "lzf.h"

#include <algorithm>
#include <cstring>

namespace segmatch {
namespace io {
namespace detail {

namespace {

constexpr size_t kMaxLiteral = 32;
constexpr size_t kMaxOffset = 8192;  // 13 bits of offset, stored minus one
constexpr size_t kMinMatch = 3;
constexpr size_t kMaxMatch = 264;  // (7 + 255) + 2
constexpr int kHashBits = 14;

uint32_t hash3(const uint8_t* p) {
  const uint32_t v = (uint32_t(p[0]) << 16) | (uint32_t(p[1]) << 8) | p[2];
  return (v * 2654435761u) >> (32 - kHashBits);
}

void emit_literals(const uint8_t* data, size_t begin, size_t end, std::vector<uint8_t>* out) {
  while (begin < end) {
    const size_t n = std::min(kMaxLiteral, end - begin);
    out->push_back(static_cast<uint8_t>(n - 1));
    out->insert(out->end(), data + begin, data + begin + n);
    begin += n;
  }
}

void emit_match(size_t length, size_t distance, std::vector<uint8_t>* out) {
  const size_t len = length - 2;
  const size_t offset = distance - 1;
  const uint8_t high = static_cast<uint8_t>(offset >> 8);
  if (len < 7) {
    out->push_back(static_cast<uint8_t>((len << 5) | high));
  } else {
    out->push_back(static_cast<uint8_t>((7u << 5) | high));
    out->push_back(static_cast<uint8_t>(len - 7));
  }
  out->push_back(static_cast<uint8_t>(offset & 0xFF));
}

}  // namespace

std::vector<uint8_t> lzf_compress(const uint8_t* data, size_t size) {
  std::vector<uint8_t> out;
  out.reserve(size + size / kMaxLiteral + 1);
  // Position + 1 of the last occurrence of each 3-byte hash (0 = none).
  std::vector<size_t> table(size_t(1) << kHashBits, 0);
  size_t literal_begin = 0;
  size_t ip = 0;
  while (ip + kMinMatch <= size) {
    const uint32_t h = hash3(data + ip);
    const size_t candidate = table[h];
    table[h] = ip + 1;
    if (candidate != 0 && ip - (candidate - 1) <= kMaxOffset &&
        std::memcmp(data + candidate - 1, data + ip, kMinMatch) == 0) {
      const size_t ref = candidate - 1;
      const size_t max_length = std::min(kMaxMatch, size - ip);
      size_t length = kMinMatch;
      while (length < max_length && data[ref + length] == data[ip + length]) ++length;
      emit_literals(data, literal_begin, ip, &out);
      emit_match(length, ip - ref, &out);
      ip += length;
      literal_begin = ip;
    } else {
      ++ip;
    }
  }
  emit_literals(data, literal_begin, size, &out);
  return out;
}

std::string lzf_decompress(const uint8_t* in, size_t in_size, uint8_t* out, size_t out_size) {
  size_t ip = 0;
  size_t op = 0;
  while (ip < in_size) {
    const size_t ctrl = in[ip++];
    if (ctrl < kMaxLiteral) {
      const size_t n = ctrl + 1;
      if (ip + n > in_size) return "literal run past the end of the compressed data";
      if (op + n > out_size) return "decompressed data larger than declared";
      std::memcpy(out + op, in + ip, n);
      ip += n;
      op += n;
      continue;
    }
    size_t len = ctrl >> 5;
    if (len == 7) {
      if (ip >= in_size) return "back reference past the end of the compressed data";
      len += in[ip++];
    }
    if (ip >= in_size) return "back reference past the end of the compressed data";
    const size_t distance = ((ctrl & 0x1F) << 8) + in[ip++] + 1;
    len += 2;
    if (distance > op) return "back reference before the start of the data";
    if (op + len > out_size) return "decompressed data larger than declared";
    for (size_t i = 0; i < len; ++i, ++op) out[op] = out[op - distance];  // may overlap
  }
  if (op != out_size) {
    return "decompressed to " + std::to_string(op) + " bytes but " + std::to_string(out_size) + " were declared";
  }
  return {};
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
