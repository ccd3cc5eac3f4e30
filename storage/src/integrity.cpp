// MapReader::check_integrity(): everything a damaged or hand-edited map file can get wrong.
#include "reader_impl.h"
#include "segment_rows.h"
#include "surface_rows.h"

#include <functional>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

constexpr size_t kMaxRowProblems = 20;  // one corrupt page can spoil thousands of rows

int64_t count(const MapReader::Impl& impl, const char* sql) {
  Statement st(impl.db.get(), sql, impl.path);
  return st.step() ? st.column_int(0) : 0;
}

void sqlite_structure(const MapReader::Impl& impl, std::vector<std::string>* problems) {
  Statement st(impl.db.get(), "PRAGMA integrity_check", impl.path);
  while (st.step()) {
    const std::string line = st.column_text(0);
    if (line != "ok") problems->push_back("integrity_check: " + line);
  }
  // SQLite 3.40's integrity_check does not look inside virtual tables.
  Statement rtree(impl.db.get(), "SELECT rtreecheck('segment_rtree')", impl.path);
  if (rtree.step() && rtree.column_text(0) != "ok") {
    problems->push_back("rtreecheck: " + rtree.column_text(0));
  }
}

void expect_count(const std::string& what, int64_t found, uint64_t recorded, std::vector<std::string>* problems) {
  if (static_cast<uint64_t>(found) == recorded) return;
  problems->push_back(what + ": map_info records " + std::to_string(recorded) + ", the file holds " +
                      std::to_string(found));
}

void counts(const MapReader::Impl& impl, std::vector<std::string>* problems) {
  expect_count("segments", count(impl, "SELECT count(*) FROM segments"), impl.segment_count, problems);
  expect_count("points", count(impl, "SELECT coalesce(sum(num_points), 0) FROM segments"), impl.point_count, problems);
  expect_count("keyframes", count(impl, "SELECT count(*) FROM trajectory"), impl.keyframe_count, problems);
  expect_count("spatial index entries", count(impl, "SELECT count(*) FROM segment_rtree"), impl.segment_count,
               problems);
  if (impl.schema_version >= 2) {
    expect_count("point rows", count(impl, "SELECT count(*) FROM segment_points"), impl.segment_count, problems);
    const int64_t strays =
        count(impl, "SELECT count(*) FROM segment_points WHERE row NOT IN (SELECT row FROM segments)");
    if (strays) problems->push_back(std::to_string(strays) + " point rows belong to no segment");
  }
  const int64_t unindexed = count(impl,
                                  "SELECT count(*) FROM segments s LEFT JOIN segment_rtree r ON r.row = s.row "
                                  "WHERE r.row IS NULL OR r.min_x != s.cx OR r.max_x != s.cx OR r.min_y != s.cy "
                                  "OR r.max_y != s.cy OR r.min_z != s.cz OR r.max_z != s.cz");
  if (unindexed) {
    problems->push_back(std::to_string(unindexed) +
                        " segments are missing from the spatial index or indexed elsewhere");
  }
  if (count(impl, "SELECT count(*) FROM trajectory") == 0) return;
  const int64_t orphans = count(impl,
                                "SELECT count(*) FROM segments WHERE keyframe IS NOT NULL AND "
                                "keyframe NOT IN (SELECT keyframe FROM trajectory)");
  if (orphans) {
    problems->push_back(std::to_string(orphans) + " segments name a keyframe that is not in the trajectory");
  }
}

void rows(const MapReader::Impl& impl, std::vector<std::string>* problems) {
  const std::string sql = select_segments_sql(impl.schema_version, "ORDER BY s.row");
  Statement st(impl.db.get(), sql.c_str(), impl.path);
  size_t bad = 0;
  Segment segment;
  while (st.step()) {
    StoredRow stored;
    read_row(st, impl.schema_version, &stored);
    try {
      decode_segment(stored, impl.path, &segment);
    } catch (const StorageError& e) {
      if (++bad <= kMaxRowProblems) problems->push_back(e.what());
    }
  }
  if (bad > kMaxRowProblems) {
    problems->push_back("... and " + std::to_string(bad - kMaxRowProblems) + " more bad rows");
  }
}

}  // namespace

std::vector<std::string> check_integrity(const MapReader::Impl& impl) {
  std::vector<std::string> problems;
  // Each part runs even when another one failed: the report lists everything found.
  const std::function<void(const MapReader::Impl&, std::vector<std::string>*)> parts[] = {
      sqlite_structure, counts, rows, [](const MapReader::Impl& i, std::vector<std::string>*) { read_classifier(i); },
      [](const MapReader::Impl& i, std::vector<std::string>* p) { check_surfaces(i, kMaxRowProblems, p); }};
  for (const auto& part : parts) {
    try {
      part(impl, &problems);
    } catch (const StorageError& e) {
      problems.push_back(e.what());
    }
  }
  return problems;
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
