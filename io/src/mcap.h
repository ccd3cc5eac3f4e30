// Internal: the pieces of the MCAP container format (https://mcap.dev/spec) shared by the
// reader and the writer: opcodes, the zlib CRC-32, a bounds-checked little-endian field reader,
// chunk compression, and random access to the file.
#pragma once

#include <segmatch/io/bag.h>
#include <segmatch/io/error.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace segmatch {
namespace io {
namespace detail {
namespace mcap {

inline constexpr std::string_view kMagic("\x89MCAP0\r\n", 8);
inline constexpr size_t kRecordPrefix = 9;               // opcode uint8 + length uint64
inline constexpr size_t kMessagePrefix = 2 + 4 + 8 + 8;  // channel, sequence, log and publish time

enum Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// "Chunk", "Message", ... or "unknown opcode 0x42".
std::string opcode_name(uint8_t opcode);

// CRC-32 as zlib's crc32() computes it (the polynomial MCAP uses): crc32(0, data, n) for one
// buffer, and chained calls continue a running value.
uint32_t crc32(uint32_t crc, const void* data, size_t n);

// Reads the fields of one record body. `where` names the file and record ("x.mcap: Channel
// record at offset 81"); `base` is the body's offset in that file (or in the decompressed chunk)
// so that errors give the offset where the bad field starts.
class FieldReader {
 public:
  FieldReader(std::string_view body, uint64_t base, std::string where)
      : body_(body), base_(base), where_(std::move(where)) {}

  uint8_t u8(const char* field) { return static_cast<uint8_t>(load(field, 1)); }
  uint16_t u16(const char* field) { return static_cast<uint16_t>(load(field, 2)); }
  uint32_t u32(const char* field) { return static_cast<uint32_t>(load(field, 4)); }
  uint64_t u64(const char* field) { return load(field, 8); }
  std::string_view string(const char* field);  // uint32 length + bytes
  std::string_view bytes(const char* field, uint64_t n) { return bytes_at(field, n, pos_); }
  // n bytes from here; errors give length_at, where the field's length was read.
  std::string_view bytes_at(const char* field, uint64_t n, size_t length_at);
  std::string_view rest() { return take(body_.size() - pos_); }
  size_t position() const { return pos_; }
  [[noreturn]] void fail(const std::string& problem) const { throw IoError(where_ + ": " + problem); }

 private:
  uint64_t load(const char* field, size_t n);
  std::string_view take(size_t n) {
    const std::string_view out = body_.substr(pos_, n);
    pos_ += n;
    return out;
  }
  std::string_view body_;
  uint64_t base_;
  std::string where_;
  size_t pos_ = 0;
};

void put_u16(std::string* out, uint16_t v);
void put_u32(std::string* out, uint32_t v);
void put_u64(std::string* out, uint64_t v);
void put_string(std::string* out, std::string_view s);  // uint32 length + bytes
void put_record(std::string* out, uint8_t opcode, std::string_view body);

// Compression strings as MCAP names them: "", "zstd", "lz4".
const char* compression_name(McapCompression compression);
std::string compress(McapCompression compression, std::string_view records);
// Decompresses a chunk's records to exactly uncompressed_size bytes and checks the CRC when it
// is not zero. A size beyond what the codec can expand `compressed` to is refused before any
// allocation, so a forged size cannot ask for more memory than the file could justify.
std::string decompress(std::string_view compression, std::string_view compressed, uint64_t uncompressed_size,
                       uint32_t uncompressed_crc, const std::string& where);

// The ros2msg schema text rosbag2 stores for a type ("sensor_msgs/msg/PointCloud2"): its .msg
// definition followed by one "====...\nMSG: pkg/Name" section per type it depends on. Empty for
// a type the project does not write.
std::string ros2msg_definition(const std::string& type);

// A file read by offset (pread): bags are gigabytes, so only the records asked for are read.
class RandomAccessFile {
 public:
  explicit RandomAccessFile(const std::string& path);  // IoError when it cannot be opened
  ~RandomAccessFile();
  RandomAccessFile(const RandomAccessFile&) = delete;
  RandomAccessFile& operator=(const RandomAccessFile&) = delete;

  uint64_t size() const { return size_; }
  // n bytes at offset; IoError "<what>: N bytes at offset K run past the end of the file (M
  // bytes)" when the file is shorter: the check comes before the allocation.
  std::string read(uint64_t offset, uint64_t n, const std::string& what) const;

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
};

}  // namespace mcap
}  // namespace detail
}  // namespace io
}  // namespace segmatch
