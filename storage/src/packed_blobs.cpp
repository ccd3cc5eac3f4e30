#include "packed_blobs.h"

#include <zstd.h>

#include <cstring>
#include <new>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

// zstd level 12: decompression runs as fast at every level, so only the build pays for a higher
// one; 12 is the last level before the build time starts to grow (README, "map size").
constexpr int kLevel = 12;
constexpr size_t kPointHeader = 36;  // schema 1's point header (segment_codec.cpp)
constexpr uint32_t kInt16 = 1, kFloat32 = 2;

// out[b * n + i] = in[i * width + b]: byte b of every item together.
void split_planes(const uint8_t* in, size_t n, size_t width, uint8_t* out) {
  for (size_t i = 0; i < n; ++i)
    for (size_t b = 0; b < width; ++b) out[b * n + i] = in[i * width + b];
}
void join_planes(const uint8_t* in, size_t n, size_t width, uint8_t* out) {
  for (size_t b = 0; b < width; ++b)
    for (size_t i = 0; i < n; ++i) out[i * width + b] = in[b * n + i];
}

// Each of the `channels` uint16 columns of `n` rows replaced by its differences (mod 2^16), or
// with `undo` by its running sums (the inverse).
void delta_code(uint8_t* body, size_t n, size_t channels, bool undo) {
  for (size_t c = 0; c < channels; ++c) {
    uint16_t previous = 0;
    for (size_t i = 0; i < n; ++i) {
      uint16_t v;
      std::memcpy(&v, body + (i * channels + c) * 2, 2);
      const uint16_t out = undo ? static_cast<uint16_t>(previous + v) : static_cast<uint16_t>(v - previous);
      previous = undo ? out : v;
      std::memcpy(body + (i * channels + c) * 2, &out, 2);
    }
  }
}

// One zstd context per thread, kept: ZSTD_compress / ZSTD_decompress set up a new one per call,
// which cost more than packing or unpacking a segment (a level-12 context is megabytes).
struct Contexts {
  ZSTD_CCtx* compress = ZSTD_createCCtx();
  ZSTD_DCtx* decompress = ZSTD_createDCtx();
  ~Contexts() {
    ZSTD_freeCCtx(compress);
    ZSTD_freeDCtx(decompress);
  }
};
Contexts& contexts() {
  thread_local Contexts c;
  if (!c.compress || !c.decompress) throw std::bad_alloc();
  return c;
}

void compress_into(const std::vector<uint8_t>& in, std::vector<uint8_t>* out) {
  const size_t at = out->size();
  out->resize(at + ZSTD_compressBound(in.size()));
  const size_t n =
      ZSTD_compressCCtx(contexts().compress, out->data() + at, out->size() - at, in.data(), in.size(), kLevel);
  if (ZSTD_isError(n)) throw std::runtime_error(std::string("zstd: ") + ZSTD_getErrorName(n));
  out->resize(at + n);
}

// Decompresses a frame that must hold exactly `size` bytes.
std::string decompress(const uint8_t* in, size_t in_size, size_t size, std::vector<uint8_t>* out) {
  const unsigned long long content = ZSTD_getFrameContentSize(in, in_size);
  if (content == ZSTD_CONTENTSIZE_ERROR) return "not a zstd frame";
  if (content != size) return "packed data holds " + std::to_string(content) + " bytes, expected " + std::to_string(size);
  out->resize(size);
  const size_t n = ZSTD_decompressDCtx(contexts().decompress, out->data(), size, in, in_size);
  if (ZSTD_isError(n)) return std::string("cannot decompress: ") + ZSTD_getErrorName(n);
  if (n != size) return "packed data decompressed to " + std::to_string(n) + " bytes, expected " + std::to_string(size);
  return {};
}

size_t point_size(uint32_t encoding) { return encoding == kInt16 ? 8 : encoding == kFloat32 ? 16 : 0; }

// int16 points: x y z delta-coded in 6 byte planes. The intensity is not kept: no stage of
// localization reads a map point's intensity, and at 16 bits it is sensor noise that packs to
// ~1.9 bytes a point against ~2.9 for x y z together (8 bits: 0.9; measured on maps/tiny-3). A
// point decodes to the header's intensity offset: the middle of the segment's range.
constexpr size_t kPackedInt16 = 6;

void pack_int16(const uint8_t* body, size_t n, std::vector<uint8_t>* planes) {
  std::vector<uint8_t> xyz(6 * n);
  for (size_t i = 0; i < n; ++i) std::memcpy(&xyz[6 * i], body + 8 * i, 6);
  delta_code(xyz.data(), n, 3, false);
  planes->resize(kPackedInt16 * n);
  split_planes(xyz.data(), n, 6, planes->data());
}

void unpack_int16(const uint8_t* planes, size_t n, uint8_t* body) {
  std::vector<uint8_t> xyz(6 * n);
  join_planes(planes, n, 6, xyz.data());
  delta_code(xyz.data(), n, 3, true);
  for (size_t i = 0; i < n; ++i) {
    std::memcpy(body + 8 * i, &xyz[6 * i], 6);
    std::memset(body + 8 * i + 6, 0, 2);  // q = 0: the header's offset
  }
}

}  // namespace

std::vector<uint8_t> pack_points(BlobView plain) {
  const auto* bytes = static_cast<const uint8_t*>(plain.data);
  uint32_t encoding = 0;
  if (plain.size >= kPointHeader) std::memcpy(&encoding, bytes, 4);
  const size_t width = point_size(encoding);
  if (width == 0 || (plain.size - kPointHeader) % width != 0)
    throw std::logic_error("pack_points: not a schema-1 point blob");
  const size_t n = (plain.size - kPointHeader) / width;
  std::vector<uint8_t> planes;
  if (encoding == kInt16) {
    pack_int16(bytes + kPointHeader, n, &planes);
  } else {
    planes.resize(n * width);
    split_planes(bytes + kPointHeader, n, width, planes.data());
  }
  std::vector<uint8_t> out(bytes, bytes + kPointHeader);
  compress_into(planes, &out);
  return out;
}

std::string unpack_points(BlobView packed, uint64_t num_points, std::vector<uint8_t>* plain) {
  if (packed.is_null || packed.size < kPointHeader) return "point blob missing or too short";
  const auto* bytes = static_cast<const uint8_t*>(packed.data);
  uint32_t encoding = 0;
  std::memcpy(&encoding, bytes, 4);
  const size_t width = point_size(encoding);
  if (width == 0) return "unknown point encoding " + std::to_string(encoding);
  if (num_points > (uint64_t{1} << 40) / width) return "implausible point count " + std::to_string(num_points);
  const size_t n = static_cast<size_t>(num_points);
  std::vector<uint8_t> planes;
  const size_t packed_width = encoding == kInt16 ? kPackedInt16 : width;
  std::string problem = decompress(bytes + kPointHeader, packed.size - kPointHeader, n * packed_width, &planes);
  if (!problem.empty()) return "points: " + problem;
  plain->resize(kPointHeader + n * width);
  std::memcpy(plain->data(), bytes, kPointHeader);
  if (encoding == kInt16) {
    unpack_int16(planes.data(), n, plain->data() + kPointHeader);
  } else {
    join_planes(planes.data(), n, width, plain->data() + kPointHeader);
  }
  return {};
}

std::vector<uint8_t> pack_esf(BlobView plain) {
  const auto* bytes = static_cast<const uint8_t*>(plain.data);
  std::vector<uint8_t> planes(plain.size), out;
  split_planes(bytes, plain.size / 4, 4, planes.data());
  compress_into(planes, &out);
  return out;
}

std::string unpack_esf(BlobView packed, size_t plain_size, std::vector<uint8_t>* plain) {
  std::vector<uint8_t> planes;
  const std::string problem =
      decompress(static_cast<const uint8_t*>(packed.data), packed.size, plain_size, &planes);
  if (!problem.empty()) return "ESF: " + problem;
  plain->resize(plain_size);
  join_planes(planes.data(), plain_size / 4, 4, plain->data());
  return {};
}

std::vector<uint8_t> pack_bytes(const std::string& plain) {
  std::vector<uint8_t> out;
  compress_into(std::vector<uint8_t>(plain.begin(), plain.end()), &out);
  return out;
}

std::string unpack_bytes(BlobView packed, size_t max_size, std::string* plain) {
  const auto* in = static_cast<const uint8_t*>(packed.data);
  const unsigned long long content = ZSTD_getFrameContentSize(in, packed.size);
  if (content == ZSTD_CONTENTSIZE_ERROR || content == ZSTD_CONTENTSIZE_UNKNOWN) return "not a zstd frame";
  if (content > max_size) return "packed data claims " + std::to_string(content) + " bytes";
  std::vector<uint8_t> bytes;
  const std::string problem = decompress(in, packed.size, static_cast<size_t>(content), &bytes);
  if (!problem.empty()) return problem;
  plain->assign(bytes.begin(), bytes.end());
  return {};
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
