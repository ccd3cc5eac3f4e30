// The byte encodings of a segment row: points (quantised, see map_writer.h), descriptor
// BLOBs and the XXH64 row checksum. Pure functions; no SQLite.
#pragma once

#include <segmatch/core/segmentation/segment.h>
#include <segmatch/storage/map_types.h>

#include "bytes.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__,
              "map BLOBs are little-endian and copied as-is; add byte swapping for this host");

// XXH64 (Yann Collet's xxHash, 64-bit variant): fast enough to verify every row at load.
uint64_t xxh64(const void* data, size_t size, uint64_t seed);

struct EncodedPoints {
  std::vector<uint8_t> blob;
  Eigen::Vector3f box_min = Eigen::Vector3f::Zero();  // of the finite points; the centroid
  Eigen::Vector3f box_max = Eigen::Vector3f::Zero();  // when there are none
};
EncodedPoints encode_points(const PointCloud& points, const Eigen::Vector3f& centroid);
// Empty string on success, else what is wrong with the blob.
std::string decode_points(BlobView blob, uint64_t num_points, PointCloud* points);

// Schema 2's int16 points in one pass: `header` is schema 1's 36-byte point header, `planes` the
// x y z deltas in 6 byte planes (packed_blobs.h); the intensity is the header's offset. The
// same floats as packing and decoding through schema 1's BLOB.
std::string decode_int16_planes(const uint8_t* header, const uint8_t* planes, uint64_t num_points, PointCloud* points);

// One `segments` row as stored (blobs are views into the caller's memory).
struct SegmentRow {
  uint64_t segment_id = 0;
  uint32_t keyframe = 0;  // kNoKeyframe when unknown
  uint32_t label = 0;
  Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
  Eigen::Vector3f box_min = Eigen::Vector3f::Zero();
  Eigen::Vector3f box_max = Eigen::Vector3f::Zero();
  uint64_t num_points = 0;
  BlobView eigen, esf, points;
};
uint64_t row_checksum(const SegmentRow& row);
uint64_t classifier_checksum(const ClassifierBlob& classifier);

BlobView eigen_blob(const Segment& segment);  // NULL view when !has_eigen
BlobView esf_blob(const Segment& segment);    // NULL view when !has_esf
// Fills everything but the points from the row; empty string on success, else the problem.
std::string decode_descriptors(const SegmentRow& row, Segment* segment);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
