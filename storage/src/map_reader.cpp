#include <segmatch/storage/map_reader.h>

#include "packed_blobs.h"
#include "reader_impl.h"
#include "schema.h"
#include "segment_rows.h"
#include "surface_rows.h"

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <thread>

namespace segmatch {
namespace storage {

using namespace detail;

namespace {

// A count in map_info sizes allocations before any row is read, so one that no file of this
// size could hold (negative, or more rows than bytes) is damage, not a request for memory
// (fuzz_map found a negative segment count reaching vector::reserve). Points are compressed,
// so only their sign is checked.
uint64_t stored_count(const MapReader::Impl& impl, const char* what, int64_t count, bool one_row_each) {
  std::error_code ec;
  const uintmax_t file_bytes = std::filesystem::file_size(impl.path, ec);
  if (count < 0 || (one_row_each && !ec && static_cast<uintmax_t>(count) > file_bytes)) {
    fail(impl.path, "the map file is corrupted: map_info records " + std::to_string(count) + " " + what +
                        ", impossible in a file of " + std::to_string(ec ? 0 : file_bytes) + " bytes");
  }
  return static_cast<uint64_t>(count);
}

void load_metadata(MapReader::Impl* impl) {
  Statement st(impl->db.get(),
               "SELECT name, frame, created_utc, tool_version, parameters_json, eigen_dims, "
               "esf_dims, segment_count, point_count, keyframe_count FROM map_info "
               "WHERE singleton = 1",
               impl->path);
  if (!st.step()) fail(impl->path, "the map file is damaged: its map_info row is missing");
  MapMetadata& m = impl->metadata;
  m.name = st.column_text(0);
  m.frame = st.column_text(1);
  m.created_utc = st.column_text(2);
  m.tool_version = st.column_text(3);
  m.parameters_json = st.column_text(4);
  m.eigen_dims = static_cast<int>(st.column_int(5));
  m.esf_dims = static_cast<int>(st.column_int(6));
  impl->segment_count = stored_count(*impl, "segments", st.column_int(7), true);
  impl->point_count = stored_count(*impl, "points", st.column_int(8), false);
  impl->keyframe_count = stored_count(*impl, "keyframes", st.column_int(9), true);
  if (m.eigen_dims != kEigenFeatureCount || m.esf_dims != kEsfBins) {
    fail(impl->path, "the map stores " + std::to_string(m.eigen_dims) + " eigen features and " +
                         std::to_string(m.esf_dims) + " ESF bins; this build uses " +
                         std::to_string(kEigenFeatureCount) + " and " + std::to_string(kEsfBins));
  }
}

// Appends the segment of the statement's current row.
void append_segment(const Statement& st, int schema_version, const std::string& path, Segments* segments,
                    std::vector<uint32_t>* keyframes) {
  StoredRow stored;
  read_row(st, schema_version, &stored);
  segments->emplace_back();
  decode_segment(stored, path, &segments->back());
  if (keyframes) keyframes->push_back(stored.row.keyframe);
}

// Rows of the segments whose centroid is within the radius, ascending. The R*Tree holds each
// centroid as a point box (float32, so exactly the stored centroid); the cube query is
// widened a little so that float rounding never loses a segment on its boundary, and the
// exact test runs on the returned centroid.
std::vector<int64_t> rows_near(const MapReader::Impl& impl, const Eigen::Vector3f& center, float radius) {
  Statement st(impl.db.get(),
               "SELECT row, min_x, min_y, min_z FROM segment_rtree WHERE max_x >= ? AND "
               "min_x <= ? AND max_y >= ? AND min_y <= ? AND max_z >= ? AND min_z <= ?",
               impl.path);
  const double slack = 1e-5 * (center.cwiseAbs().maxCoeff() + radius) + 1e-6;
  for (int a = 0; a < 3; ++a) {
    st.bind_double(1 + 2 * a, double(center[a]) - radius - slack);
    st.bind_double(2 + 2 * a, double(center[a]) + radius + slack);
  }
  std::vector<int64_t> rows;
  while (st.step()) {
    const Eigen::Vector3f c(float(st.column_double(1)), float(st.column_double(2)), float(st.column_double(3)));
    if ((c - center).squaredNorm() <= radius * radius) rows.push_back(st.column_int(0));
  }
  std::sort(rows.begin(), rows.end());
  return rows;
}

}  // namespace

std::optional<ClassifierBlob> detail::read_classifier(const MapReader::Impl& impl) {
  Statement st(impl.db.get(), "SELECT format, bytes, checksum FROM classifier", impl.path);
  if (!st.step()) return std::nullopt;
  ClassifierBlob blob;
  blob.format = st.column_text(0);
  const BlobView bytes = st.column_blob(1);
  if (impl.schema_version >= 2) {  // packed; the checksum is over the unpacked bytes
    constexpr size_t kMaxClassifierBytes = size_t{1} << 30;
    const std::string problem = unpack_bytes(bytes, kMaxClassifierBytes, &blob.bytes);
    if (!problem.empty()) fail(impl.path, "the map file is corrupted: classifier: " + problem);
  } else if (bytes.size) {
    blob.bytes.assign(static_cast<const char*>(bytes.data), bytes.size);
  }
  if (classifier_checksum(blob) != static_cast<uint64_t>(st.column_int(2))) {
    fail(impl.path, "the map file is corrupted: classifier checksum mismatch");
  }
  return blob;
}

namespace {

Connection open_read_only(const std::string& path) {
  Connection db = open_connection(path, SQLITE_OPEN_READONLY);
  // Memory-mapped reads hand out BLOBs without copying pages into SQLite's cache (up to the
  // 2 GB limit Debian's build allows; larger files fall back to reads beyond it).
  // locking_mode EXCLUSIVE: the shared lock taken at the first read is kept, so a lazy point
  // read makes no lock, unlock and change-counter check of its own (system calls that were much
  // of a read's time; docs/measurements.md, "Map size and storage"). Nothing ever writes a published map in place
  // (writers rename a new file over it), so the lock holds nobody up.
  exec(db.get(), "PRAGMA mmap_size = 2147418112; PRAGMA locking_mode = EXCLUSIVE", path);
  return db;
}

// Opens every connection; false when `path` named another file afterwards (the map was
// replaced meanwhile), so that all connections are known to read the same file.
bool open_connections(MapReader::Impl* impl) {
  const MapFileInfo before = check_map_file(impl->path);
  impl->schema_version = before.schema_version;
  impl->db = open_read_only(impl->path);
  const unsigned threads = std::clamp(std::thread::hardware_concurrency(), 1u, 4u);
  impl->loaders.clear();
  for (unsigned i = 1; i < threads; ++i) impl->loaders.push_back(open_read_only(impl->path));
  struct stat after;
  return ::stat(impl->path.c_str(), &after) == 0 && after.st_dev == before.device && after.st_ino == before.inode;
}

}  // namespace

std::unique_ptr<Statement> StatementPool::take(const MapReader::Impl& impl) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!idle_.empty()) {
    std::unique_ptr<Statement> st = std::move(idle_.back());
    idle_.pop_back();
    return st;
  }
  const size_t k = made_++ % (1 + impl.loaders.size());
  sqlite3* db = k == 0 ? impl.db.get() : impl.loaders[k - 1].get();
  return std::make_unique<Statement>(db, sql_, impl.path);
}

void StatementPool::give_back(std::unique_ptr<Statement> st) {
  st->reset();
  std::lock_guard<std::mutex> lock(mutex_);
  idle_.push_back(std::move(st));
}

MapReader::Impl::Impl() : point_reads(kSelectPointsSql), tile_reads(kSelectSurfaceTileSql) {}

MapReader MapReader::open(const std::string& path) {
  auto impl = std::make_unique<Impl>();
  impl->path = path;
  for (int attempt = 0; !open_connections(impl.get()); ++attempt) {
    if (attempt == 3) fail(path, "the map file keeps being replaced while opening it");
  }
  check_tables(impl->db.get(), path, impl->schema_version);
  load_metadata(impl.get());
  impl->surfaces = read_surface_layer(impl->db.get(), path, impl->schema_version);
  return MapReader(std::move(impl));
}

MapReader::MapReader(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MapReader::MapReader(MapReader&&) noexcept = default;
MapReader& MapReader::operator=(MapReader&&) noexcept = default;
MapReader::~MapReader() = default;

const std::string& MapReader::path() const { return impl_->path; }
const MapMetadata& MapReader::metadata() const { return impl_->metadata; }
int MapReader::schema_version() const { return impl_->schema_version; }

Segments MapReader::load_segments(std::vector<uint32_t>* keyframe_of_segment) const {
  return load_all_segments(*impl_, keyframe_of_segment, true);
}

Segments MapReader::load_segments_without_points(std::vector<uint32_t>* keyframe_of_segment) const {
  return load_all_segments(*impl_, keyframe_of_segment, false);
}

void MapReader::stop_mapping() const {
  exec(impl_->db.get(), "PRAGMA mmap_size = 0", impl_->path);
  for (const Connection& c : impl_->loaders) exec(c.get(), "PRAGMA mmap_size = 0", impl_->path);
}

PointCloud MapReader::read_points(size_t index) const {
  const int64_t row = static_cast<int64_t>(index) + 1;  // rows are 1..N in load order
  PointCloud points;
  if (impl_->schema_version < 2) {  // the points live in the row, under its one checksum
    Statement st(impl_->db.get(), select_segments_sql(1, "WHERE s.row = ?").c_str(), impl_->path);
    st.bind_int(1, row);
    if (!st.step()) fail(impl_->path, "no segment row " + std::to_string(row));
    StoredRow stored;
    read_row(st, 1, &stored);
    Segment segment;
    decode_segment(stored, impl_->path, &segment);
    return std::move(segment.points);
  }
  std::unique_ptr<Statement> st = impl_->point_reads.take(*impl_);
  st->bind_int(1, row);
  if (!st->step()) fail(impl_->path, "no segment row " + std::to_string(row));
  decode_points_row(*st, row, impl_->path, &points);  // throws: the statement is dropped
  impl_->point_reads.give_back(std::move(st));
  return points;
}

std::optional<SurfaceLayer> MapReader::surfaces() const { return impl_->surfaces; }

PointCloud MapReader::surface_tile(int32_t tile_x, int32_t tile_y) const {
  PointCloud points;
  if (!impl_->surfaces) return points;
  std::unique_ptr<Statement> st = impl_->tile_reads.take(*impl_);
  st->bind_int(1, tile_x);
  st->bind_int(2, tile_y);
  if (st->step()) decode_surface_row(*st, 0, tile_x, tile_y, impl_->path, &points);  // throws: dropped
  impl_->tile_reads.give_back(std::move(st));
  return points;
}

std::vector<std::pair<int32_t, int32_t>> MapReader::surface_tile_keys() const { return read_surface_tile_keys(*impl_); }

Segments MapReader::segments_near(const Eigen::Vector3f& center, float radius_m,
                                  std::vector<uint32_t>* keyframe_of_segment) const {
  if (!center.allFinite() || std::isnan(radius_m)) {
    throw std::invalid_argument("MapReader::segments_near: non-finite center or radius");
  }
  if (keyframe_of_segment) keyframe_of_segment->clear();
  Segments segments;
  if (radius_m < 0.f) return segments;
  const std::vector<int64_t> rows = rows_near(*impl_, center, radius_m);
  const std::string sql = select_segments_sql(impl_->schema_version, "WHERE s.row = ?");
  Statement st(impl_->db.get(), sql.c_str(), impl_->path);
  segments.reserve(rows.size());
  for (int64_t row : rows) {
    st.bind_int(1, row);
    if (!st.step()) {
      fail(impl_->path, "the map file is corrupted: the spatial index names segment row " + std::to_string(row) +
                            ", which does not exist");
    }
    append_segment(st, impl_->schema_version, impl_->path, &segments, keyframe_of_segment);
    st.reset();
  }
  return segments;
}

std::vector<Keyframe> MapReader::trajectory() const {
  Statement st(impl_->db.get(), "SELECT * FROM trajectory ORDER BY keyframe", impl_->path);
  std::vector<Keyframe> keyframes;
  while (st.step()) {
    Keyframe k;
    k.index = static_cast<uint32_t>(st.column_int(0));
    k.time_s = st.column_double(1);
    Eigen::Matrix3d r;
    for (int i = 0; i < 9; ++i) r(i / 3, i % 3) = st.column_double(2 + i);
    k.T_map_sensor.linear() = r;
    k.T_map_sensor.translation() << st.column_double(11), st.column_double(12), st.column_double(13);
    keyframes.push_back(k);
  }
  return keyframes;
}

std::optional<ClassifierBlob> MapReader::classifier() const { return read_classifier(*impl_); }

MapStats MapReader::stats() const {
  MapStats stats;
  stats.segments = impl_->segment_count;
  stats.points = impl_->point_count;
  const std::vector<Keyframe> keyframes = trajectory();
  stats.keyframes = keyframes.size();
  for (size_t i = 1; i < keyframes.size(); ++i) {
    stats.trajectory_length_m +=
        (keyframes[i].T_map_sensor.translation() - keyframes[i - 1].T_map_sensor.translation()).norm();
  }
  Statement st(impl_->db.get(), "SELECT count(*) FROM classifier", impl_->path);
  stats.has_classifier = st.step() && st.column_int(0) > 0;
  return stats;
}

std::vector<std::string> MapReader::check_integrity() const { return detail::check_integrity(*impl_); }

}  // namespace storage
}  // namespace segmatch
