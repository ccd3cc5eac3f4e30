// Reading `segments` rows back into Segments, shared by the reader, the integrity check and
// the upgrade. Schema 1 keeps each segment's points in its row; schemas 2 and 3 keep them,
// packed, in segment_points (one row per segment, same row number) with their own checksum.
#pragma once

#include <segmatch/core/segmentation/segment.h>

#include "segment_codec.h"
#include "sqlite_util.h"

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

// "SELECT <the columns read_row() reads> FROM segments s ... " + tail, where tail may use the
// alias s (e.g. "WHERE s.row = ?"). Without points, schema 2 reads no page of segment_points
// (the points column reads as NULL); schema 1 keeps them in the row and reads them anyway.
std::string select_segments_sql(int schema_version, const std::string& tail, bool with_points = true);

struct StoredRow {
  int schema_version = 1;
  int64_t row_id = 0;
  uint64_t checksum = 0;         // schema 1: the whole row; schema 2: all but the points
  uint64_t points_checksum = 0;  // schema 2
  SegmentRow row;                // blobs point into the statement: valid until its next step()
};
void read_row(const Statement& st, int schema_version, StoredRow* stored);

// Schema 2's checksum of a packed point BLOB, bound to its row and point count.
uint64_t points_checksum(int64_t row_id, uint64_t num_points, BlobView points);

// Verifies the checksums and decodes; throws StorageError ("... is corrupted: segment row N:
// ...") on any mismatch. Without points, schema 2's points (not read) are neither checked nor
// decoded, and segment->points is left empty.
void decode_segment(const StoredRow& stored, const std::string& path, Segment* segment, bool with_points = true);

// Schema 2: checks and decodes the points of one row, as kSelectPointsSql reads them.
extern const char* const kSelectPointsSql;  // binds the row; columns: num_points, points, checksum
void decode_points_row(const Statement& st, int64_t row_id, const std::string& path, PointCloud* points);

// A stored row with schema 1's BLOBs (a plain point BLOB, ESF as 640 floats), unpacked into
// `buffers` where the schema packs them: what MapWriter stores again. Checksums are the caller's
// (decode_segment first); a BLOB that does not unpack throws StorageError.
struct PlainBlobs {
  std::vector<uint8_t> points;
  EsfDescriptor esf{};
};
SegmentRow plain_row(const StoredRow& stored, const std::string& path, PlainBlobs* buffers);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
