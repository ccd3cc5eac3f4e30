// Reading `segments` rows back into Segments, shared by the reader and the integrity check.
#pragma once

#include <segmatch/core/segment.h>

#include "segment_codec.h"
#include "sqlite_util.h"

#include <cstdint>
#include <string>

namespace segmatch {
namespace storage {
namespace detail {

// Column list matching read_row(); append "FROM segments ..." (alias s).
extern const char* const kSelectSegmentColumns;

struct StoredRow {
  int64_t row_id = 0;
  uint64_t checksum = 0;
  SegmentRow row;  // blobs point into the statement: valid until its next step()
};
void read_row(const Statement& st, StoredRow* stored);

// Verifies the checksum and decodes; throws StorageError ("... is corrupted: segment row N:
// ...") on any mismatch.
void decode_segment(const StoredRow& stored, const std::string& path, Segment* segment);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
