#include "segment_rows.h"

namespace segmatch {
namespace storage {
namespace detail {

const char* const kSelectSegmentColumns =
    "SELECT s.row, s.segment_id, s.keyframe, s.label, s.cx, s.cy, s.cz, s.min_x, s.min_y, "
    "s.min_z, s.max_x, s.max_y, s.max_z, s.num_points, s.checksum, s.eigen, s.esf, s.points ";

namespace {

Eigen::Vector3f vector_at(const Statement& st, int first) {
  return {static_cast<float>(st.column_double(first)), static_cast<float>(st.column_double(first + 1)),
          static_cast<float>(st.column_double(first + 2))};
}

}  // namespace

void read_row(const Statement& st, StoredRow* stored) {
  SegmentRow& row = stored->row;
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
}

void decode_segment(const StoredRow& stored, const std::string& path, Segment* segment) {
  const auto corrupted = [&](const std::string& problem) {
    fail(path, "the map file is corrupted: segment row " + std::to_string(stored.row_id) + ": " +
                   problem);
  };
  if (row_checksum(stored.row) != stored.checksum) corrupted("checksum mismatch");
  std::string problem = decode_descriptors(stored.row, segment);
  if (problem.empty()) {
    problem = decode_points(stored.row.points, stored.row.num_points, &segment->points);
  }
  if (!problem.empty()) corrupted(problem);
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
