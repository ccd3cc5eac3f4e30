#include "segment_rows.h"

#include "packed_blobs.h"

namespace segmatch {
namespace storage {
namespace detail {

std::string select_segments_sql(int schema_version, const std::string& tail, bool with_points) {
  const std::string common =
      "SELECT s.row, s.segment_id, s.keyframe, s.label, s.cx, s.cy, s.cz, s.min_x, s.min_y, "
      "s.min_z, s.max_x, s.max_y, s.max_z, s.num_points, s.checksum, s.eigen, s.esf, ";
  // LEFT JOIN: a missing points row reads as a NULL BLOB and is reported, not skipped.
  if (schema_version >= 2 && !with_points) return common + "NULL, 0 FROM segments s " + tail;
  if (schema_version >= 2)
    return common + "p.points, p.checksum FROM segments s LEFT JOIN segment_points p ON p.row = s.row " + tail;
  return common + "s.points FROM segments s " + tail;
}

namespace {

Eigen::Vector3f vector_at(const Statement& st, int first) {
  return {static_cast<float>(st.column_double(first)), static_cast<float>(st.column_double(first + 1)),
          static_cast<float>(st.column_double(first + 2))};
}

}  // namespace

void read_row(const Statement& st, int schema_version, StoredRow* stored) {
  SegmentRow& row = stored->row;
  stored->schema_version = schema_version;
  stored->row_id = st.column_int(0);
  row.segment_id = static_cast<uint64_t>(st.column_int(1));
  row.keyframe = st.is_null(2) ? kNoKeyframe : static_cast<uint32_t>(st.column_int(2));
  row.label = static_cast<uint32_t>(st.column_int(3));
  row.centroid = vector_at(st, 4);
  row.box_min = vector_at(st, 7);
  row.box_max = vector_at(st, 10);
  row.num_points = static_cast<uint64_t>(st.column_int(13));
  stored->checksum = static_cast<uint64_t>(st.column_int(14));
  row.eigen = st.column_blob(15);
  row.esf = st.column_blob(16);
  row.points = st.column_blob(17);
  stored->points_checksum = schema_version >= 2 ? static_cast<uint64_t>(st.column_int(18)) : 0;
}

uint64_t points_checksum(int64_t row_id, uint64_t num_points, BlobView points) {
  const uint64_t h = xxh64(&num_points, sizeof(num_points), static_cast<uint64_t>(row_id));
  return points.is_null ? h : xxh64(points.data, points.size, h);
}

namespace {

// Schema 2's points of one row: checked against their checksum, unpacked, decoded. Empty
// string on success, else the problem.
// A packed ESF: zstd byte planes in schema 2, u16 sparse from schema 3 (packed_blobs.h).
std::string unpack_stored_esf(int schema_version, BlobView packed, EsfDescriptor* esf) {
  return schema_version >= 3 ? unpack_esf_sparse(packed, esf) : unpack_esf(packed, esf);
}

std::string decode_packed_points(int64_t row_id, uint64_t num_points, BlobView blob, uint64_t checksum,
                                 PointCloud* out) {
  if (points_checksum(row_id, num_points, blob) != checksum) return "points checksum mismatch";
  return unpack_points(blob, num_points, out);
}

}  // namespace

void decode_segment(const StoredRow& stored, const std::string& path, Segment* segment, bool with_points) {
  const auto corrupted = [&](const std::string& problem) {
    fail(path, "the map file is corrupted: segment row " + std::to_string(stored.row_id) + ": " + problem);
  };
  segment->points.clear();
  if (stored.schema_version < 2) {  // one checksum over the whole row, points included
    if (row_checksum(stored.row) != stored.checksum) corrupted("checksum mismatch");
    std::string problem = decode_descriptors(stored.row, segment);
    if (problem.empty() && with_points)
      problem = decode_points(stored.row.points, stored.row.num_points, &segment->points);
    if (!problem.empty()) corrupted(problem);
    return;
  }
  SegmentRow row = stored.row;
  row.points = {};  // schemas 2 and 3: the row's checksum leaves the points to their own
  if (row_checksum(row) != stored.checksum) corrupted("checksum mismatch");
  const BlobView esf = row.esf;
  row.esf = {};  // packed: decoded below, straight into the segment
  std::string problem = decode_descriptors(row, segment);
  if (problem.empty() && !esf.is_null) {
    problem = unpack_stored_esf(stored.schema_version, esf, &segment->esf);
    segment->has_esf = true;
  }
  if (problem.empty() && with_points)
    problem = decode_packed_points(stored.row_id, row.num_points, stored.row.points, stored.points_checksum,
                                   &segment->points);
  if (!problem.empty()) corrupted(problem);
}

const char* const kSelectPointsSql =
    "SELECT s.num_points, p.points, p.checksum FROM segments s LEFT JOIN segment_points p ON p.row = s.row "
    "WHERE s.row = ?";

void decode_points_row(const Statement& st, int64_t row_id, const std::string& path, PointCloud* out) {
  const std::string problem = decode_packed_points(row_id, static_cast<uint64_t>(st.column_int(0)), st.column_blob(1),
                                                   static_cast<uint64_t>(st.column_int(2)), out);
  if (!problem.empty()) fail(path, "the map file is corrupted: segment row " + std::to_string(row_id) + ": " + problem);
}

SegmentRow plain_row(const StoredRow& stored, const std::string& path, PlainBlobs* buffers) {
  SegmentRow row = stored.row;
  if (stored.schema_version < 2) return row;
  std::string problem = unpack_points(row.points, row.num_points, &buffers->points);
  row.points = {buffers->points.data(), buffers->points.size(), false};
  if (problem.empty() && !row.esf.is_null) {
    problem = unpack_stored_esf(stored.schema_version, row.esf, &buffers->esf);
    row.esf = {buffers->esf.data(), sizeof(buffers->esf), false};
  }
  if (!problem.empty())
    fail(path, "the map file is corrupted: segment row " + std::to_string(stored.row_id) + ": " + problem);
  return row;
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
