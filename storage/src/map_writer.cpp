#include <segmatch/storage/map_writer.h>

#include "file_util.h"
#include "packed_blobs.h"
#include "reader_impl.h"
#include "schema.h"
#include "segment_codec.h"
#include "segment_rows.h"
#include "sqlite_util.h"
#include "surface_rows.h"

#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstring>
#include <ctime>
#include <set>
#include <stdexcept>

namespace segmatch {
namespace storage {

using namespace detail;

namespace {

const char* const kInsertSegment =
    "INSERT INTO segments (row, segment_id, keyframe, label, cx, cy, cz, min_x, min_y, min_z, "
    "max_x, max_y, max_z, num_points, checksum, eigen, esf) "
    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)";
const char* const kInsertPoints = "INSERT INTO segment_points (row, checksum, points) VALUES (?, ?, ?)";
const char* const kInsertRtree = "INSERT INTO segment_rtree VALUES (?, ?, ?, ?, ?, ?, ?)";
const char* const kInsertKeyframe = "INSERT INTO trajectory VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)";

std::string now_utc_iso8601() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

void validate(const MapMetadata& metadata) {
  if (metadata.eigen_dims != kEigenFeatureCount || metadata.esf_dims != kEsfBins) {
    throw std::invalid_argument("MapWriter: metadata descriptor sizes (" + std::to_string(metadata.eigen_dims) + ", " +
                                std::to_string(metadata.esf_dims) + ") differ from this build's (" +
                                std::to_string(kEigenFeatureCount) + ", " + std::to_string(kEsfBins) + ")");
  }
  if (metadata.frame.empty()) throw std::invalid_argument("MapWriter: metadata.frame is empty");
}

void validate(const Segments& segments, const std::vector<uint32_t>& keyframes) {
  if (!keyframes.empty() && keyframes.size() != segments.size()) {
    throw std::invalid_argument("MapWriter::add_segments: " + std::to_string(keyframes.size()) +
                                " keyframe indices for " + std::to_string(segments.size()) + " segments");
  }
  for (const Segment& segment : segments) {
    if (!segment.centroid.allFinite()) {
      throw std::invalid_argument("MapWriter::add_segments: segment " + std::to_string(segment.id) +
                                  " has a non-finite centroid");
    }
  }
}

void validate(const std::vector<Keyframe>& keyframes) {
  std::set<uint32_t> seen;
  for (const Keyframe& k : keyframes) {
    if (!seen.insert(k.index).second) {
      throw std::invalid_argument("MapWriter::set_trajectory: keyframe index " + std::to_string(k.index) +
                                  " appears twice");
    }
    // SQLite would store a NaN as NULL: refuse it here with a message instead.
    if (!std::isfinite(k.time_s) || !k.T_map_sensor.matrix().allFinite()) {
      throw std::invalid_argument("MapWriter::set_trajectory: keyframe " + std::to_string(k.index) +
                                  " has a non-finite time or pose");
    }
  }
}

void bind_vector(Statement& st, int first, const Eigen::Vector3f& v) {
  for (int a = 0; a < 3; ++a) st.bind_double(first + a, v[a]);
}

void bind_optional_blob(Statement& st, int i, BlobView blob) {
  if (blob.is_null) {
    st.bind_null(i);
  } else {
    st.bind_blob(i, blob.data, blob.size);
  }
}

}  // namespace

struct MapWriter::Impl {
  std::string path, temporary_path;
  std::string compact_path;  // temporary_path + ".compact": the table-by-table copy commit() publishes
  bool overwrite = false;
  Connection db;  // declared before the statements: destroyed after them
  std::unique_ptr<Statement> insert_segment, insert_points, insert_rtree;
  int64_t next_row = 1;
  uint64_t point_count = 0;
  size_t keyframe_count = 0;
  bool finished = false;  // committed: nothing to clean up
  bool failed = false;    // a write threw: the transaction's content is unknown

  ~Impl() {
    if (finished) return;
    insert_segment.reset();
    insert_points.reset();
    insert_rtree.reset();
    db.reset();  // uncommitted transaction => rolled back
    ::unlink(temporary_path.c_str());
    ::unlink(compact_path.c_str());
  }

  void require_writable(const char* operation) const {
    if (finished) throw std::logic_error(std::string("MapWriter::") + operation + " after commit()");
    if (failed) fail(temporary_path, std::string("cannot ") + operation + ": an earlier write failed");
  }

  // Runs one write; a throw marks the writer as failed so that commit() refuses.
  template <typename Fn>
  void write(const char* operation, Fn&& fn) {
    require_writable(operation);
    try {
      fn();
    } catch (...) {
      failed = true;
      throw;
    }
  }

  void insert(const Segment& segment, uint32_t keyframe);
  // A row whose points are a schema-1 BLOB (encode_points()) and whose ESF is raw floats
  // (quantised here).
  void insert_row(SegmentRow row);
  void publish();
};

void MapWriter::Impl::insert(const Segment& segment, uint32_t keyframe) {
  const EncodedPoints encoded = encode_points(segment.points, segment.centroid);
  SegmentRow row;
  row.segment_id = segment.id;
  row.keyframe = keyframe;
  row.label = segment.label;
  row.centroid = segment.centroid;
  row.box_min = encoded.box_min;
  row.box_max = encoded.box_max;
  row.num_points = segment.points.size();
  row.eigen = eigen_blob(segment);
  row.esf = esf_blob(segment);
  row.points = {encoded.blob.data(), encoded.blob.size(), false};
  insert_row(row);
}

void MapWriter::Impl::insert_row(SegmentRow row) {
  const std::vector<uint8_t> points = pack_points(row.points);
  std::vector<uint8_t> esf;
  if (!row.esf.is_null) {
    if (row.esf.size != sizeof(EsfDescriptor)) throw std::logic_error("insert_row: the ESF is not 640 floats");
    EsfDescriptor plain;
    std::memcpy(plain.data(), row.esf.data, sizeof(plain));
    esf = pack_esf_sparse(plain);
    row.esf = {esf.data(), esf.size(), false};
  }
  row.points = {};  // the points have their own row and checksum
  Statement& st = *insert_segment;
  st.bind_int(1, next_row);
  st.bind_int(2, static_cast<int64_t>(row.segment_id));  // uint64 kept bit for bit
  if (row.keyframe == kNoKeyframe)
    st.bind_null(3);
  else
    st.bind_int(3, row.keyframe);
  st.bind_int(4, row.label);
  bind_vector(st, 5, row.centroid);
  bind_vector(st, 8, row.box_min);
  bind_vector(st, 11, row.box_max);
  st.bind_int(14, static_cast<int64_t>(row.num_points));
  st.bind_int(15, static_cast<int64_t>(row_checksum(row)));
  bind_optional_blob(st, 16, row.eigen);
  bind_optional_blob(st, 17, row.esf);
  st.run();
  Statement& pt = *insert_points;
  pt.bind_int(1, next_row);
  pt.bind_int(2,
              static_cast<int64_t>(points_checksum(next_row, row.num_points, {points.data(), points.size(), false})));
  pt.bind_blob(3, points.data(), points.size());
  pt.run();

  // A point box per centroid: segments_near() asks which centroids lie in a query cube.
  Statement& rt = *insert_rtree;
  rt.bind_int(1, next_row);
  for (int a = 0; a < 3; ++a) {
    rt.bind_double(2 + 2 * a, row.centroid[a]);
    rt.bind_double(3 + 2 * a, row.centroid[a]);
  }
  rt.run();
  ++next_row;
  point_count += row.num_points;
}

void MapWriter::Impl::publish() {
  {
    Statement counts(db.get(), "UPDATE map_info SET segment_count = ?, point_count = ?, keyframe_count = ?",
                     temporary_path);
    counts.bind_int(1, next_row - 1);
    counts.bind_int(2, static_cast<int64_t>(point_count));
    counts.bind_int(3, static_cast<int64_t>(keyframe_count));
    counts.run();
  }  // finalized: sqlite3_close() refuses while a statement lives
  insert_segment.reset();
  insert_points.reset();
  insert_rtree.reset();
  exec(db.get(), "COMMIT", temporary_path);
  // Segments and their points were inserted in turn, so each table's pages are spread over the
  // whole file; a copy written table by table keeps the segments (what a server loads) in one
  // stretch, and opening a city map reads that stretch instead of faulting in pages from
  // everywhere (docs/measurements.md, "Map size and storage").
  {
    Statement vacuum(db.get(), "VACUUM INTO ?", temporary_path);
    vacuum.bind_text(1, compact_path);
    vacuum.run();
  }  // finalized before the close
  const int rc = sqlite3_close(db.release());
  if (rc != SQLITE_OK) fail_sqlite(nullptr, rc, temporary_path, "closing");
  ::unlink(temporary_path.c_str());
  // Data on disk before the name points at it: a crash never exposes a half-written file.
  fsync_path(compact_path, false);
  move_into_place(compact_path, path, overwrite);
  fsync_path(parent_folder(path), true);
}

MapWriter MapWriter::create(const std::string& path, const MapMetadata& metadata, bool overwrite) {
  validate(metadata);
  check_target(path, overwrite);
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  impl->overwrite = overwrite;
  // pid and a counter: unique among running writers, also two in one process.
  static std::atomic<uint64_t> writers{0};
  impl->temporary_path = path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(writers++);
  impl->compact_path = impl->temporary_path + ".compact";
  ::unlink(impl->compact_path.c_str());
  ::unlink(impl->temporary_path.c_str());  // left by a killed process that had our pid
  impl->db = open_connection(impl->temporary_path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  sqlite3* db = impl->db.get();
  // Small pages: a BLOB's overflow chain wastes half a page on average, which with schema 1's
  // 64 KiB pages was about as much as the packed data itself; 1 KiB pages cost nothing
  // measurable when loading (docs/measurements.md, "Map size and storage"). The journal may live in memory and syncs
  // may be skipped because a failed build only loses the temporary file, and commit() fsyncs the finished file itself.
  exec(db,
       "PRAGMA page_size = 1024; PRAGMA journal_mode = MEMORY; PRAGMA synchronous = OFF;"
       "PRAGMA cache_size = -65536; BEGIN",
       impl->temporary_path);
  create_schema(db, impl->temporary_path);

  Statement info(db, "INSERT INTO map_info VALUES (1, ?, ?, ?, ?, ?, ?, ?, 0, 0, 0)", impl->temporary_path);
  info.bind_text(1, metadata.name);
  info.bind_text(2, metadata.frame);
  info.bind_text(3, metadata.created_utc.empty() ? now_utc_iso8601() : metadata.created_utc);
  info.bind_text(4, metadata.tool_version);
  info.bind_text(5, metadata.parameters_json);
  info.bind_int(6, metadata.eigen_dims);
  info.bind_int(7, metadata.esf_dims);
  info.run();
  impl->insert_segment = std::make_unique<Statement>(db, kInsertSegment, impl->temporary_path);
  impl->insert_points = std::make_unique<Statement>(db, kInsertPoints, impl->temporary_path);
  impl->insert_rtree = std::make_unique<Statement>(db, kInsertRtree, impl->temporary_path);
  return MapWriter(std::move(impl));
}

MapWriter::MapWriter(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MapWriter::MapWriter(MapWriter&&) noexcept = default;
MapWriter& MapWriter::operator=(MapWriter&&) noexcept = default;
MapWriter::~MapWriter() = default;

const std::string& MapWriter::path() const { return impl_->path; }
const std::string& MapWriter::temporary_path() const { return impl_->temporary_path; }

void MapWriter::add_segments(const Segments& segments, const std::vector<uint32_t>& keyframe_of_segment) {
  impl_->require_writable("add_segments");
  validate(segments, keyframe_of_segment);
  impl_->write("add_segments", [&] {
    for (size_t i = 0; i < segments.size(); ++i) {
      impl_->insert(segments[i], keyframe_of_segment.empty() ? kNoKeyframe : keyframe_of_segment[i]);
    }
  });
}

void MapWriter::set_trajectory(const std::vector<Keyframe>& keyframes) {
  impl_->require_writable("set_trajectory");
  validate(keyframes);
  impl_->write("set_trajectory", [&] {
    sqlite3* db = impl_->db.get();
    Statement(db, "DELETE FROM trajectory", impl_->temporary_path).run();
    Statement insert(db, kInsertKeyframe, impl_->temporary_path);
    for (const Keyframe& k : keyframes) {
      insert.bind_int(1, k.index);
      insert.bind_double(2, k.time_s);
      const Eigen::Matrix3d r = k.T_map_sensor.linear();
      for (int i = 0; i < 9; ++i) insert.bind_double(3 + i, r(i / 3, i % 3));
      for (int a = 0; a < 3; ++a) insert.bind_double(12 + a, k.T_map_sensor.translation()[a]);
      insert.run();
    }
    impl_->keyframe_count = keyframes.size();
  });
}

void MapWriter::set_classifier(const ClassifierBlob& classifier) {
  impl_->write("set_classifier", [&] {
    Statement insert(impl_->db.get(), "INSERT OR REPLACE INTO classifier VALUES (1, ?, ?, ?)", impl_->temporary_path);
    insert.bind_text(1, classifier.format);
    const std::vector<uint8_t> packed = pack_bytes(classifier.bytes);
    insert.bind_blob(2, packed.data(), packed.size());
    insert.bind_int(3, static_cast<int64_t>(classifier_checksum(classifier)));
    insert.run();
  });
}

void MapWriter::set_surfaces(const PointCloud& points_map, float leaf_m, float tile_m) {
  impl_->require_writable("set_surfaces");
  validate_surfaces(points_map, leaf_m, tile_m);
  impl_->write("set_surfaces",
               [&] { write_surfaces(impl_->db.get(), impl_->temporary_path, points_map, leaf_m, tile_m); });
}

void MapWriter::commit() {
  impl_->write("commit", [&] { impl_->publish(); });
  impl_->finished = true;
}

int upgrade_map(const std::string& old_path, const std::string& new_path, bool overwrite) {
  const MapReader old = MapReader::open(old_path);
  const int from = old.schema_version();
  if (from == kSchemaVersion)
    fail(old_path, "the map is already at schema " + std::to_string(from) + ": nothing to upgrade");
  MapWriter writer = MapWriter::create(new_path, old.metadata(), overwrite);
  const MapReader::Impl& in = *old.impl_;
  writer.impl_->write("upgrade", [&] {
    Statement st(in.db.get(), select_segments_sql(from, "ORDER BY s.row").c_str(), in.path);
    StoredRow stored;
    Segment verified;
    PlainBlobs plain;
    while (st.step()) {
      read_row(st, from, &stored);
      decode_segment(stored, in.path, &verified);  // checksums and BLOBs checked before re-storing
      // The same point bytes, packed: no re-quantisation; the ESF is quantised.
      writer.impl_->insert_row(plain_row(stored, in.path, &plain));
    }
  });
  writer.set_trajectory(old.trajectory());
  if (const std::optional<ClassifierBlob> classifier = old.classifier()) writer.set_classifier(*classifier);
  writer.commit();
  return from;
}

}  // namespace storage
}  // namespace segmatch
