// MCAP building blocks (mcap.h): opcode names, CRC-32, field reading and writing, chunk
// compression with libzstd and liblz4's frame format, and pread-based file access.
#include "mcap.h"

#include <fcntl.h>
#include <lz4frame.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <memory>
#include <new>

namespace segmatch {
namespace io {
namespace detail {
namespace mcap {

std::string opcode_name(uint8_t opcode) {
  static const char* kNames[] = {"Header",     "Footer",       "Schema",        "Channel",       "Message",
                                 "Chunk",      "MessageIndex", "ChunkIndex",    "Attachment",    "AttachmentIndex",
                                 "Statistics", "Metadata",     "MetadataIndex", "SummaryOffset", "DataEnd"};
  if (opcode >= 1 && opcode <= 0x0F) return kNames[opcode - 1];
  const char* digits = "0123456789abcdef";
  return std::string("unknown opcode 0x") + digits[opcode >> 4] + digits[opcode & 15];
}

// Slicing by 8 (eight tables, eight bytes a step): a byte at a time made the CRC the largest
// cost of reading a bag (docs/measurements.md, "Input: bags and folders": segmatch-bench-bag).
uint32_t crc32(uint32_t crc, const void* data, size_t n) {
  static const std::array<std::array<uint32_t, 256>, 8> table = [] {
    std::array<std::array<uint32_t, 256>, 8> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; ++i)
      for (size_t s = 1; s < 8; ++s) t[s][i] = (t[s - 1][i] >> 8) ^ t[0][t[s - 1][i] & 0xFF];
    return t;
  }();
  const uint8_t* p = static_cast<const uint8_t*>(data);
  crc = ~crc;
  for (; n >= 8; n -= 8, p += 8) {
    const uint32_t lo = (static_cast<uint32_t>(p[0]) | static_cast<uint32_t>(p[1]) << 8 |
                         static_cast<uint32_t>(p[2]) << 16 | static_cast<uint32_t>(p[3]) << 24) ^
                        crc;
    crc = table[7][lo & 0xFF] ^ table[6][(lo >> 8) & 0xFF] ^ table[5][(lo >> 16) & 0xFF] ^ table[4][lo >> 24] ^
          table[3][p[4]] ^ table[2][p[5]] ^ table[1][p[6]] ^ table[0][p[7]];
  }
  for (; n > 0; --n, ++p) crc = table[0][(crc ^ *p) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

uint64_t FieldReader::load(const char* field, size_t n) {
  if (body_.size() - pos_ < n) {
    fail("field " + std::string(field) + " needs " + std::to_string(n) + " bytes at offset " +
         std::to_string(base_ + pos_) + ", the record has " + std::to_string(body_.size() - pos_) + " left");
  }
  uint64_t v = 0;
  for (size_t i = 0; i < n; ++i) v |= uint64_t{static_cast<uint8_t>(body_[pos_ + i])} << (8 * i);
  pos_ += n;
  return v;
}

std::string_view FieldReader::string(const char* field) {
  const size_t at = pos_;
  return bytes_at(field, u32(field), at);
}

std::string_view FieldReader::bytes_at(const char* field, uint64_t n, size_t length_at) {
  if (n > body_.size() - pos_) {
    fail("field " + std::string(field) + ": length " + std::to_string(n) + " at offset " +
         std::to_string(base_ + length_at) + " runs past the end of the record (" +
         std::to_string(body_.size() - pos_) + " bytes left)");
  }
  return take(static_cast<size_t>(n));
}

void put_u16(std::string* out, uint16_t v) {
  for (int i = 0; i < 2; ++i) out->push_back(static_cast<char>(v >> (8 * i)));
}
void put_u32(std::string* out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>(v >> (8 * i)));
}
void put_u64(std::string* out, uint64_t v) {
  for (int i = 0; i < 8; ++i) out->push_back(static_cast<char>(v >> (8 * i)));
}
void put_string(std::string* out, std::string_view s) {
  put_u32(out, static_cast<uint32_t>(s.size()));
  out->append(s.data(), s.size());
}
void put_record(std::string* out, uint8_t opcode, std::string_view body) {
  out->push_back(static_cast<char>(opcode));
  put_u64(out, body.size());
  out->append(body.data(), body.size());
}

const char* compression_name(McapCompression compression) {
  switch (compression) {
    case McapCompression::kZstd: return "zstd";
    case McapCompression::kLz4: return "lz4";
    default: return "";
  }
}

std::string compress(McapCompression compression, std::string_view records) {
  std::string out;
  if (compression == McapCompression::kZstd) {
    out.resize(ZSTD_compressBound(records.size()));
    const size_t n = ZSTD_compress(&out[0], out.size(), records.data(), records.size(), 3);
    if (ZSTD_isError(n)) throw IoError(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    out.resize(n);
  } else if (compression == McapCompression::kLz4) {
    LZ4F_preferences_t prefs;
    std::memset(&prefs, 0, sizeof(prefs));
    prefs.frameInfo.contentSize = records.size();
    out.resize(LZ4F_compressFrameBound(records.size(), &prefs));
    const size_t n = LZ4F_compressFrame(&out[0], out.size(), records.data(), records.size(), &prefs);
    if (LZ4F_isError(n)) throw IoError(std::string("lz4 compression failed: ") + LZ4F_getErrorName(n));
    out.resize(n);
  } else {
    out.assign(records.data(), records.size());
  }
  return out;
}

namespace {

// The most a codec can expand its input: a zstd RLE block turns 4 bytes into 128 KiB, an lz4
// sequence grows by 255 bytes per byte. Valid data never exceeds it.
uint64_t max_expansion(std::string_view compression, size_t compressed) {
  if (compression == "zstd") return uint64_t{compressed} * 32768 + 131072;
  return uint64_t{compressed} * 256 + 65536;
}

// A frame written in one call (as MCAP writers do) states its content size: when the chunk is
// that one frame, the two sizes must agree before anything is allocated, which catches a damaged
// uncompressed_size that the expansion bound alone would let through.
void check_zstd_content_size(std::string_view in, uint64_t uncompressed_size, const std::string& where) {
  const unsigned long long stated = ZSTD_getFrameContentSize(in.data(), in.size());
  if (stated == ZSTD_CONTENTSIZE_ERROR) throw IoError(where + ": zstd decompression failed: not a zstd frame");
  const size_t frame = ZSTD_findFrameCompressedSize(in.data(), in.size());
  if (stated != ZSTD_CONTENTSIZE_UNKNOWN && !ZSTD_isError(frame) && frame == in.size() && stated != uncompressed_size) {
    throw IoError(where + ": the zstd frame holds " + std::to_string(stated) + " bytes, uncompressed_size says " +
                  std::to_string(uncompressed_size));
  }
}

size_t zstd_decompress(std::string_view in, std::string* out, const std::string& where) {
  const size_t n = ZSTD_decompress(&(*out)[0], out->size(), in.data(), in.size());
  if (ZSTD_isError(n)) throw IoError(where + ": zstd decompression failed: " + ZSTD_getErrorName(n));
  return n;
}

size_t lz4_decompress(std::string_view in, std::string* out, const std::string& where) {
  LZ4F_dctx* raw = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&raw, LZ4F_VERSION))) {
    throw IoError(where + ": cannot create an lz4 decompression context");
  }
  const std::unique_ptr<LZ4F_dctx, decltype(&LZ4F_freeDecompressionContext)> ctx(raw, &LZ4F_freeDecompressionContext);
  size_t in_pos = 0, out_pos = 0, hint = 1;
  // Frames may follow each other; LZ4F_decompress returns 0 at the end of each.
  while (in_pos < in.size()) {
    size_t src = in.size() - in_pos, dst = out->size() - out_pos;
    hint =
        LZ4F_decompress(ctx.get(), out->empty() ? nullptr : &(*out)[out_pos], &dst, in.data() + in_pos, &src, nullptr);
    if (LZ4F_isError(hint)) {
      throw IoError(where + ": lz4 decompression failed: " + LZ4F_getErrorName(hint));
    }
    in_pos += src;
    out_pos += dst;
    if (src == 0 && dst == 0) {
      throw IoError(where + ": lz4 data decompresses to more than the chunk's uncompressed_size " +
                    std::to_string(out->size()));
    }
  }
  if (hint != 0) throw IoError(where + ": lz4 decompression failed: the frame is truncated");
  return out_pos;
}

}  // namespace

std::string decompress(std::string_view compression, std::string_view compressed, uint64_t uncompressed_size,
                       uint32_t uncompressed_crc, const std::string& where) {
  if (compression != "" && compression != "zstd" && compression != "lz4") {
    throw IoError(where + ": compression '" + std::string(compression) + "' is not supported (zstd, lz4 or none)");
  }
  if (compression == "" && uncompressed_size != compressed.size()) {
    throw IoError(where + ": uncompressed chunk of " + std::to_string(compressed.size()) +
                  " bytes but uncompressed_size says " + std::to_string(uncompressed_size));
  }
  if (uncompressed_size > max_expansion(compression, compressed.size())) {
    throw IoError(where + ": uncompressed_size " + std::to_string(uncompressed_size) + " is more than " +
                  std::string(compression) + " can expand " + std::to_string(compressed.size()) + " bytes to");
  }
  if (compression == "zstd") check_zstd_content_size(compressed, uncompressed_size, where);
  std::string out;
  if (compression == "") {
    out.assign(compressed.data(), compressed.size());
  } else {
    try {
      out.resize(static_cast<size_t>(uncompressed_size));
    } catch (const std::bad_alloc&) {  // within the bound, yet more than this machine has
      throw IoError(where + ": cannot allocate " + std::to_string(uncompressed_size) + " bytes for the chunk");
    }
    const size_t n =
        compression == "zstd" ? zstd_decompress(compressed, &out, where) : lz4_decompress(compressed, &out, where);
    if (n != uncompressed_size) {
      throw IoError(where + ": " + std::string(compression) + " data decompresses to " + std::to_string(n) +
                    " bytes, uncompressed_size says " + std::to_string(uncompressed_size));
    }
  }
  // Zero means the writer did not compute it (the spec allows that).
  const uint32_t crc = uncompressed_crc == 0 ? 0 : crc32(0, out.data(), out.size());
  if (crc != uncompressed_crc) {
    throw IoError(where + ": CRC mismatch: the records' CRC-32 is " + std::to_string(crc) + ", uncompressed_crc says " +
                  std::to_string(uncompressed_crc));
  }
  return out;
}

RandomAccessFile::RandomAccessFile(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw IoError(path + ": cannot open: " + std::strerror(errno));
  struct stat st;
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    throw IoError(path + ": not a regular file");
  }
  size_ = static_cast<uint64_t>(st.st_size);
}

RandomAccessFile::~RandomAccessFile() {
  if (fd_ >= 0) ::close(fd_);
}

std::string RandomAccessFile::read(uint64_t offset, uint64_t n, const std::string& what) const {
  if (offset > size_ || n > size_ - offset) {
    throw IoError(what + ": " + std::to_string(n) + " bytes at offset " + std::to_string(offset) +
                  " run past the end of the file (" + std::to_string(size_) + " bytes): truncated?");
  }
  std::string out(static_cast<size_t>(n), '\0');
  size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd_, &out[done], n - done, static_cast<off_t>(offset + done));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) throw IoError(path_ + ": read error at offset " + std::to_string(offset + done));
    done += static_cast<size_t>(got);
  }
  return out;
}

}  // namespace mcap
}  // namespace detail
}  // namespace io
}  // namespace segmatch
