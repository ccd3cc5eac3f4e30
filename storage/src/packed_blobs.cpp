#include "packed_blobs.h"

#include <segmatch/core/description/esf_quantization.h>
#include <segmatch/storage/map_types.h>

#include "segment_codec.h"

#include <zstd.h>

#include <bitset>
#include <cstring>
#include <new>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

// zstd level 12: decompression runs as fast at every level, so only the build pays for a higher
// one; 12 is the last level before the build time starts to grow (docs/measurements.md, "Map size and storage").
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

}  // namespace

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
  if (content != size)
    return "packed data holds " + std::to_string(content) + " bytes, expected " + std::to_string(size);
  out->resize(size);
  const size_t n = ZSTD_decompressDCtx(contexts().decompress, out->data(), size, in, in_size);
  if (ZSTD_isError(n)) return std::string("cannot decompress: ") + ZSTD_getErrorName(n);
  if (n != size) return "packed data decompressed to " + std::to_string(n) + " bytes, expected " + std::to_string(size);
  return {};
}

namespace {

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

std::string unpack_points(BlobView packed, uint64_t num_points, PointCloud* points) {
  if (packed.is_null || packed.size < kPointHeader) return "point blob missing or too short";
  const auto* bytes = static_cast<const uint8_t*>(packed.data);
  uint32_t encoding = 0;
  std::memcpy(&encoding, bytes, 4);
  if (encoding != kInt16) {  // float32 points: through schema 1's BLOB, as rare as they are
    std::vector<uint8_t> plain;
    std::string problem = unpack_points(packed, num_points, &plain);
    return problem.empty() ? decode_points({plain.data(), plain.size(), false}, num_points, points) : problem;
  }
  if (num_points > (uint64_t{1} << 40) / kPackedInt16) return "implausible point count " + std::to_string(num_points);
  thread_local std::vector<uint8_t> planes;  // kept: a server reads a few dozen segments a query
  const size_t n = static_cast<size_t>(num_points);
  const std::string problem = decompress(bytes + kPointHeader, packed.size - kPointHeader, n * kPackedInt16, &planes);
  if (!problem.empty()) return "points: " + problem;
  return decode_int16_planes(bytes, planes.data(), num_points, points);
}

std::string unpack_esf(BlobView packed, EsfDescriptor* esf) {
  constexpr size_t kSize = sizeof(EsfDescriptor);
  std::vector<uint8_t> planes;
  const std::string problem = decompress(static_cast<const uint8_t*>(packed.data), packed.size, kSize, &planes);
  if (!problem.empty()) return "ESF: " + problem;
  join_planes(planes.data(), kSize / 4, 4, reinterpret_cast<uint8_t*>(esf->data()));
  return {};
}

namespace {
constexpr size_t kEsfMaskBytes = kEsfBins / 8;
static_assert(kEsfBins % 8 == 0, "the mask has no spare bits");
}  // namespace

std::vector<uint8_t> pack_esf_sparse(const EsfDescriptor& esf) {
  const QuantizedEsf q = quantize_esf(esf, kMapEsfMinExponent, kMapEsfMaxExponent);
  std::vector<uint8_t> out(1 + kEsfMaskBytes, 0);
  out[0] = static_cast<uint8_t>(static_cast<int8_t>(q.exponent));
  for (int i = 0; i < kEsfBins; ++i) {
    if (q.mantissas[i] == 0) continue;
    out[1 + i / 8] |= static_cast<uint8_t>(1u << (i % 8));
    out.push_back(static_cast<uint8_t>(q.mantissas[i] & 0xff));
    out.push_back(static_cast<uint8_t>(q.mantissas[i] >> 8));
  }
  return out;
}

std::string unpack_esf_sparse(BlobView packed, EsfDescriptor* esf) {
  const auto* bytes = static_cast<const uint8_t*>(packed.data);
  if (packed.is_null || packed.size < 1 + kEsfMaskBytes) return "ESF blob missing or too short";
  const int exponent = static_cast<int8_t>(bytes[0]);
  if (exponent < kMapEsfMinExponent || exponent > kMapEsfMaxExponent)
    return "ESF exponent " + std::to_string(exponent) + " out of range";
  const uint8_t* mask = bytes + 1;
  size_t nonzero = 0;
  for (size_t b = 0; b < kEsfMaskBytes; ++b) nonzero += std::bitset<8>(mask[b]).count();
  if (packed.size != 1 + kEsfMaskBytes + 2 * nonzero)
    return "ESF blob has " + std::to_string(packed.size) + " bytes, its mask says " +
           std::to_string(1 + kEsfMaskBytes + 2 * nonzero);
  // Without a branch per bin (the mask is a coin toss where a histogram thins out): a zero bin
  // reads the next mantissa and keeps 0; the copy gives that read a place past the last one.
  uint8_t mantissas[2 * kEsfBins + 2] = {};
  std::memcpy(mantissas, mask + kEsfMaskBytes, 2 * nonzero);
  const float scale = esf_scale(exponent);
  size_t k = 0;
  bool zero_marked = false;
  for (int i = 0; i < kEsfBins; ++i) {
    const unsigned bit = mask[i / 8] >> (i % 8) & 1u;
    const unsigned m = mantissas[2 * k] | unsigned{mantissas[2 * k + 1]} << 8;
    zero_marked |= bit && m == 0;
    (*esf)[i] = dequantize_esf_bin(static_cast<uint16_t>(m * bit), scale);
    k += bit;
  }
  if (zero_marked) return "ESF bin marked non-zero holds 0";
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
