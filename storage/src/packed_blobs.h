// Schema 2's packed BLOBs: schema 1's BLOBs compressed with zstd.
// Points: schema 1's 36-byte header, then the body with x y z delta-coded along the points and
// split into byte planes (neighbouring points differ by a few centimetres, so the high bytes
// are nearly constant), and the intensity at 8 bits instead of 16 (packed_blobs.cpp says why),
// compressed. Unpacking restores schema 1's x y z bytes exactly, so a map decodes to the same
// coordinates whichever schema holds it. float32 points (schema 1's fallback) are kept whole.
// ESF: the 640 float32 split into byte planes, compressed (most bins are zero); lossless.
#pragma once

#include "bytes.h"

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

std::vector<uint8_t> pack_esf(BlobView plain);
// The packed frame must hold exactly plain_size bytes.
std::string unpack_esf(BlobView packed, size_t plain_size, std::vector<uint8_t>* plain);

// The classifier's bytes (an OpenCV YAML forest: text, ~8x smaller packed).
std::vector<uint8_t> pack_bytes(const std::string& plain);
// At most max_size bytes (checked before anything is allocated).
std::string unpack_bytes(BlobView packed, size_t max_size, std::string* plain);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
