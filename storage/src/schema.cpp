#include "schema.h"

#include "sqlite_util.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <set>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

// Literal values, not spliced text: PRAGMAs take no bound parameters. create_schema() reads
// both back and compares them with kApplicationId / kSchemaVersion.
const char* const kSchemaSql = R"sql(
PRAGMA application_id = 1399278960;
PRAGMA user_version = 4;
CREATE TABLE map_info (
  singleton INTEGER PRIMARY KEY CHECK (singleton = 1),
  name TEXT NOT NULL, frame TEXT NOT NULL, created_utc TEXT NOT NULL,
  tool_version TEXT NOT NULL, parameters_json TEXT NOT NULL,
  eigen_dims INTEGER NOT NULL, esf_dims INTEGER NOT NULL,
  segment_count INTEGER NOT NULL, point_count INTEGER NOT NULL, keyframe_count INTEGER NOT NULL);
CREATE TABLE segments (
  row INTEGER PRIMARY KEY,
  segment_id INTEGER NOT NULL, keyframe INTEGER, label INTEGER NOT NULL,
  cx REAL NOT NULL, cy REAL NOT NULL, cz REAL NOT NULL,
  min_x REAL NOT NULL, min_y REAL NOT NULL, min_z REAL NOT NULL,
  max_x REAL NOT NULL, max_y REAL NOT NULL, max_z REAL NOT NULL,
  num_points INTEGER NOT NULL, checksum INTEGER NOT NULL,
  eigen BLOB, esf BLOB);
CREATE TABLE segment_points (
  row INTEGER PRIMARY KEY, checksum INTEGER NOT NULL, points BLOB NOT NULL);
CREATE VIRTUAL TABLE segment_rtree USING rtree (row, min_x, max_x, min_y, max_y, min_z, max_z);
CREATE TABLE trajectory (
  keyframe INTEGER PRIMARY KEY, time_s REAL NOT NULL,
  r00 REAL NOT NULL, r01 REAL NOT NULL, r02 REAL NOT NULL,
  r10 REAL NOT NULL, r11 REAL NOT NULL, r12 REAL NOT NULL,
  r20 REAL NOT NULL, r21 REAL NOT NULL, r22 REAL NOT NULL,
  tx REAL NOT NULL, ty REAL NOT NULL, tz REAL NOT NULL);
CREATE TABLE classifier (
  singleton INTEGER PRIMARY KEY CHECK (singleton = 1),
  format TEXT NOT NULL, bytes BLOB NOT NULL, checksum INTEGER NOT NULL);
CREATE TABLE surface_layer (
  singleton INTEGER PRIMARY KEY CHECK (singleton = 1),
  leaf_m REAL NOT NULL, tile_m REAL NOT NULL,
  tile_count INTEGER NOT NULL, point_count INTEGER NOT NULL, stored_bytes INTEGER NOT NULL);
CREATE TABLE surface_tiles (
  tile_x INTEGER NOT NULL, tile_y INTEGER NOT NULL, point_count INTEGER NOT NULL,
  checksum INTEGER NOT NULL, points BLOB NOT NULL, PRIMARY KEY (tile_x, tile_y));
)sql";

const char* const kTables[] = {"map_info", "segments", "segment_rtree", "trajectory", "classifier"};
const char* const kTablesSince2[] = {"segment_points"};
const char* const kTablesSince4[] = {"surface_layer", "surface_tiles"};

int64_t pragma_value(sqlite3* db, const char* sql, const std::string& path) {
  Statement pragma(db, sql, path);
  return pragma.step() ? pragma.column_int(0) : 0;
}

uint32_t be32(const unsigned char* p) {
  return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3];
}

std::string hex32(uint32_t v) {
  char text[16];
  std::snprintf(text, sizeof(text), "0x%08X", v);
  return text;
}

struct stat regular_file(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) fail(path, "map file does not exist");
    fail(path, std::string("cannot access the map file: ") + std::strerror(errno));
  }
  if (S_ISDIR(st.st_mode)) fail(path, "is a directory, expected a map file");
  if (!S_ISREG(st.st_mode)) fail(path, "is not a regular file, expected a map file");
  if (st.st_size == 0) fail(path, "empty file (0 bytes), not a segment map");
  return st;
}

// The fields of the 100-byte SQLite header (https://sqlite.org/fileformat.html) we check.
void check_version(uint32_t stored, const std::string& path) {
  const int version = static_cast<int32_t>(stored);
  if (version > kSchemaVersion) {
    fail(path, "map schema version " + std::to_string(version) + " is newer than this build can read (up to " +
                   std::to_string(kSchemaVersion) + "); update segmatch");
  }
  if (version < kOldestReadableSchemaVersion) {
    fail(path, "map schema version " + std::to_string(version) + " is older than this build can read (oldest " +
                   std::to_string(kOldestReadableSchemaVersion) + "); rebuild the map");
  }
}

void check_size(const unsigned char* header, off_t size, const std::string& path) {
  uint32_t page_size = uint32_t(header[16]) << 8 | header[17];
  if (page_size == 1) page_size = 65536;
  if (page_size < 512 || page_size > 65536 || (page_size & (page_size - 1)) != 0) {
    fail(path, "the map file is corrupted: invalid page size " + std::to_string(page_size));
  }
  if (size % page_size != 0) {
    fail(path, "the map file is truncated or damaged: " + std::to_string(size) + " bytes is not a whole number of " +
                   std::to_string(page_size) + "-byte pages");
  }
  // The page count at offset 28 is valid when offset 92 matches the change counter.
  const uint64_t pages = be32(header + 28);
  if (be32(header + 92) == be32(header + 24) && uint64_t(size) < pages * page_size) {
    fail(path, "the map file is truncated: its header says " + std::to_string(pages * page_size) +
                   " bytes, the file has " + std::to_string(size));
  }
}

}  // namespace

void create_schema(sqlite3* db, const std::string& path) {
  exec(db, kSchemaSql, path);
  if (pragma_value(db, "PRAGMA application_id", path) != int32_t(kApplicationId) ||
      pragma_value(db, "PRAGMA user_version", path) != kSchemaVersion) {
    throw std::logic_error("schema.cpp: kSchemaSql disagrees with kApplicationId/kSchemaVersion");
  }
}

MapFileInfo check_map_file(const std::string& path) {
  const struct stat st = regular_file(path);
  const off_t size = st.st_size;
  unsigned char header[100] = {};
  std::ifstream in(path, std::ios::binary);
  in.read(reinterpret_cast<char*>(header), sizeof(header));
  if (!in && !in.eof()) fail(path, "cannot read the map file");
  static const char kMagic[] = "SQLite format 3";  // 16 bytes with its NUL
  if (size < 100 || std::memcmp(header, kMagic, sizeof(kMagic)) != 0) {
    fail(path, "not an SQLite database (no SQLite header), so not a segment map" +
                   std::string(size < 100 ? " (or truncated to " + std::to_string(size) + " bytes)" : ""));
  }
  const uint32_t application_id = be32(header + 68);
  if (application_id != kApplicationId) {
    fail(path, "an SQLite database of another application, not a segment map (application_id " + hex32(application_id) +
                   ", expected " + hex32(kApplicationId) + ")");
  }
  check_version(be32(header + 60), path);
  check_size(header, size, path);
  return {static_cast<int32_t>(be32(header + 60)), st.st_dev, st.st_ino};
}

void check_tables(sqlite3* db, const std::string& path, int schema_version) {
  Statement tables(db, "SELECT name FROM sqlite_master WHERE type = 'table'", path);
  std::set<std::string> found;
  while (tables.step()) found.insert(tables.column_text(0));
  std::vector<std::string> expected(std::begin(kTables), std::end(kTables));
  if (schema_version >= 2) expected.insert(expected.end(), std::begin(kTablesSince2), std::end(kTablesSince2));
  if (schema_version >= 4) expected.insert(expected.end(), std::begin(kTablesSince4), std::end(kTablesSince4));
  for (const std::string& table : expected) {
    if (!found.count(table)) fail(path, "the map file is incomplete or damaged: no table " + table);
  }
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
