// Reading `segments` rows back into Segments, shared by the reader, the integrity check and
// the upgrade. Schema 1 keeps each segment's points in its row; schema 2 keeps them, packed,
// in segment_points (one row per segment, same row number) with their own checksum.
#pragma once

#include <segmatch/core/segment.h>

#include "segment_codec.h"
#include "sqlite_util.h"

#include <cstdint>
#include <string>

namespace segmatch {
namespace storage {
namespace detail {

// "SELECT <the columns read_row() reads> FROM segments s ... " + tail, where tail may use the
// alias s (e.g. "WHERE s.row = ?").
std::string select_segments_sql(int schema_version, const std::string& tail);

struct StoredRow {
  int schema_version = 1;
  int64_t row_id = 0;
  uint64_t checksum = 0;         // schema 1: the whole row; schema 2: all but the points
  uint64_t points_checksum = 0;  // schema 2
  SegmentRow row;  // blobs point into the statement: valid until its next step()
};
void read_row(const Statement& st, int schema_version, StoredRow* stored);

// Schema 2's checksum of a packed point BLOB, bound to its row and point count.
uint64_t points_checksum(int64_t row_id, uint64_t num_points, BlobView points);

// Verifies the checksums and decodes; throws StorageError ("... is corrupted: segment row N:
// ...") on any mismatch.
void decode_segment(const StoredRow& stored, const std::string& path, Segment* segment);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
