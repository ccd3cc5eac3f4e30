// The packed BLOBs of schemas 2 and 3: schema 1's BLOBs compressed with zstd.
// Points: schema 1's 36-byte header, then the body with x y z delta-coded along the points and
// split into byte planes (neighbouring points differ by a few centimetres, so the high bytes
// are nearly constant), without the intensity (packed_blobs.cpp says why), compressed. Unpacking restores schema 1's x
// y z bytes exactly, so a map decodes to the same coordinates whichever schema holds it. float32 points (schema 1's
// fallback) are kept whole. ESF (schema 2): the 640 float32 split into byte planes, compressed; lossless. Schema 3
// stores ESF quantised and sparse instead (below).
#pragma once

#include "bytes.h"

#include <segmatch/core/segmentation/segment.h>

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

// `plain` is a schema-1 point BLOB (encode_points()); its body must be whole points.
std::vector<uint8_t> pack_points(BlobView plain);
// Empty string on success, else what is wrong. The packed frame must hold exactly the body of
// num_points points (checked before anything is allocated).
std::string unpack_points(BlobView packed, uint64_t num_points, std::vector<uint8_t>* plain);
// The same decoded in one pass (what loading and lazy reads use): the floats that decoding the
// schema-1 BLOB gives.
std::string unpack_points(BlobView packed, uint64_t num_points, PointCloud* points);

// Schema 2's ESF, unpacked into `esf`.
std::string unpack_esf(BlobView packed, EsfDescriptor* esf);

// Schema 3's ESF: quantised to u16 (core/esf_quantization.h, as LOCALIZE_SEGMENTS sends it) and
// sparse: the int8 exponent, an 80-byte mask of the non-zero bins (bit i % 8 of byte i / 8),
// then their mantissas, u16 little-endian. No entropy coder: decoding a zstd frame per segment
// was most of opening a city map, and this is smaller anyway (docs/measurements.md, "Map size and storage").
std::vector<uint8_t> pack_esf_sparse(const EsfDescriptor& esf);
// Empty string on success, else what is wrong with the blob.
std::string unpack_esf_sparse(BlobView packed, EsfDescriptor* esf);

// `in` compressed with zstd at the level of every packed BLOB, appended to `out`.
void compress_into(const std::vector<uint8_t>& in, std::vector<uint8_t>* out);
// Decompresses a frame that must hold exactly `size` bytes into `out`; empty string on
// success, else what is wrong.
std::string decompress(const uint8_t* in, size_t in_size, size_t size, std::vector<uint8_t>* out);

// The classifier's bytes (an OpenCV YAML forest: text, ~8x smaller packed).
std::vector<uint8_t> pack_bytes(const std::string& plain);
// At most max_size bytes (checked before anything is allocated).
std::string unpack_bytes(BlobView packed, size_t max_size, std::string* plain);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
