#include "surface_rows.h"

#include "surface_codec.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

std::string tile_name(int64_t x, int64_t y) {
  return "surface tile (" + std::to_string(x) + ", " + std::to_string(y) + ")";
}

std::string point_text(const Point& p) {
  return "(" + std::to_string(p.x) + ", " + std::to_string(p.y) + ", " + std::to_string(p.z) + ")";
}

bool in_int32(int64_t v) {
  return v >= std::numeric_limits<int32_t>::min() && v <= std::numeric_limits<int32_t>::max();
}

void check_size(const char* name, float value) {
  if (!std::isfinite(value) || !(value > 0.f)) {
    throw std::invalid_argument(std::string("MapWriter::set_surfaces: ") + name + " must be finite and > 0, got " +
                                std::to_string(value));
  }
}

}  // namespace

void validate_surfaces(const PointCloud& points, float leaf_m, float tile_m) {
  check_size("leaf_m", leaf_m);
  check_size("tile_m", tile_m);
  for (size_t i = 0; i < points.size(); ++i) {
    const Point& p = points[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      throw std::invalid_argument("MapWriter::set_surfaces: point " + std::to_string(i) + " is not finite " +
                                  point_text(p));
    }
    // Compared in double: a quotient beyond int64 would make the conversion undefined.
    const double tx = std::floor(double(p.x) / tile_m), ty = std::floor(double(p.y) / tile_m);
    if (!(std::fabs(tx) < 2147483647.0 && std::fabs(ty) < 2147483647.0)) {
      throw std::invalid_argument("MapWriter::set_surfaces: point " + std::to_string(i) + " " + point_text(p) +
                                  " lies beyond the tile grid of " + std::to_string(tile_m) + " m tiles");
    }
  }
}

void write_surfaces(sqlite3* db, const std::string& path, const PointCloud& points, float leaf_m, float tile_m) {
  Statement(db, "DELETE FROM surface_tiles", path).run();
  Statement(db, "DELETE FROM surface_layer", path).run();
  // (tile key, point index), sorted: each tile's points together, tiles in key order.
  std::vector<std::pair<int64_t, size_t>> keyed(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const int64_t x = surface_tile_index(points[i].x, tile_m), y = surface_tile_index(points[i].y, tile_m);
    keyed[i] = {surface_tile_key(static_cast<int32_t>(x), static_cast<int32_t>(y)), i};
  }
  std::sort(keyed.begin(), keyed.end());
  Statement insert(db,
                   "INSERT INTO surface_tiles (tile_x, tile_y, point_count, checksum, points) "
                   "VALUES (?, ?, ?, ?, ?)",
                   path);
  SurfaceLayer layer{leaf_m, tile_m, 0, 0, 0};
  PointCloud tile;
  for (size_t begin = 0, end = 0; begin < keyed.size(); begin = end) {
    tile.clear();
    for (end = begin; end < keyed.size() && keyed[end].first == keyed[begin].first; ++end)
      tile.push_back(points[keyed[end].second]);
    const int32_t x = surface_tile_x(keyed[begin].first), y = surface_tile_y(keyed[begin].first);
    const std::vector<uint8_t> blob = encode_surface_tile(tile, x, y, tile_m, leaf_m);
    const BlobView view{blob.data(), blob.size(), false};
    insert.bind_int(1, x);
    insert.bind_int(2, y);
    insert.bind_int(3, static_cast<int64_t>(tile.size()));
    insert.bind_int(4, static_cast<int64_t>(surface_tile_checksum(x, y, tile.size(), view)));
    insert.bind_blob(5, blob.data(), blob.size());
    insert.run();
    ++layer.tile_count;
    layer.point_count += tile.size();
    layer.stored_bytes += blob.size();
  }
  Statement row(db, "INSERT INTO surface_layer VALUES (1, ?, ?, ?, ?, ?)", path);
  row.bind_double(1, layer.leaf_m);
  row.bind_double(2, layer.tile_m);
  row.bind_int(3, static_cast<int64_t>(layer.tile_count));
  row.bind_int(4, static_cast<int64_t>(layer.point_count));
  row.bind_int(5, static_cast<int64_t>(layer.stored_bytes));
  row.run();
}

std::optional<SurfaceLayer> read_surface_layer(sqlite3* db, const std::string& path, int schema_version) {
  if (schema_version < 4) return std::nullopt;
  Statement st(db, "SELECT leaf_m, tile_m, tile_count, point_count, stored_bytes FROM surface_layer", path);
  if (!st.step()) return std::nullopt;
  SurfaceLayer layer;
  layer.leaf_m = static_cast<float>(st.column_double(0));
  layer.tile_m = static_cast<float>(st.column_double(1));
  const int64_t counts[3] = {st.column_int(2), st.column_int(3), st.column_int(4)};
  // tile_m divides every query's coordinates: a damaged one must not reach it.
  if (!std::isfinite(layer.leaf_m) || !(layer.leaf_m > 0.f) || !std::isfinite(layer.tile_m) || !(layer.tile_m > 0.f) ||
      *std::min_element(counts, counts + 3) < 0) {
    fail(path, "the map file is corrupted: its surface_layer row holds impossible values");
  }
  layer.tile_count = static_cast<uint64_t>(counts[0]);
  layer.point_count = static_cast<uint64_t>(counts[1]);
  layer.stored_bytes = static_cast<uint64_t>(counts[2]);
  return layer;
}

const char* const kSelectSurfaceTileSql =
    "SELECT point_count, checksum, points FROM surface_tiles WHERE tile_x = ? AND tile_y = ?";

void decode_surface_row(const Statement& st, int first, int32_t tile_x, int32_t tile_y, const std::string& path,
                        PointCloud* points) {
  const int64_t count = st.column_int(first);
  const BlobView blob = st.column_blob(first + 2);
  std::string problem;
  if (count < 0) {
    problem = "negative point count";
  } else if (surface_tile_checksum(tile_x, tile_y, uint64_t(count), blob) != uint64_t(st.column_int(first + 1))) {
    problem = "checksum mismatch";
  } else {
    problem = decode_surface_tile(blob, uint64_t(count), points);
  }
  if (!problem.empty()) fail(path, "the map file is corrupted: " + tile_name(tile_x, tile_y) + ": " + problem);
}

std::vector<std::pair<int32_t, int32_t>> read_surface_tile_keys(const MapReader::Impl& impl) {
  std::vector<std::pair<int32_t, int32_t>> keys;
  if (!impl.surfaces) return keys;
  // The primary key's index holds both columns: no page of a tile's points is read.
  Statement st(impl.db.get(), "SELECT tile_x, tile_y FROM surface_tiles ORDER BY tile_x, tile_y", impl.path);
  while (st.step()) {
    const int64_t x = st.column_int(0), y = st.column_int(1);
    if (!in_int32(x) || !in_int32(y))
      fail(impl.path, "the map file is corrupted: " + tile_name(x, y) + " is impossible");
    keys.emplace_back(static_cast<int32_t>(x), static_cast<int32_t>(y));
  }
  return keys;
}

namespace {

int64_t count(const MapReader::Impl& impl, const char* sql) {
  Statement st(impl.db.get(), sql, impl.path);
  return st.step() ? st.column_int(0) : 0;
}

void expect_count(const std::string& what, int64_t found, uint64_t recorded, std::vector<std::string>* problems) {
  if (static_cast<uint64_t>(found) == recorded) return;
  problems->push_back(what + ": surface_layer records " + std::to_string(recorded) + ", the file holds " +
                      std::to_string(found));
}

// What is wrong with one tile row, empty when nothing: its checksum and points, and every point
// within its tile's square (a tile stored under another key would be sought in the wrong place).
std::string check_tile(const MapReader::Impl& impl, const Statement& st, PointCloud* points) {
  const int64_t x = st.column_int(0), y = st.column_int(1);
  if (!in_int32(x) || !in_int32(y)) return tile_name(x, y) + " is impossible";
  try {
    decode_surface_row(st, 2, int32_t(x), int32_t(y), impl.path, points);
  } catch (const StorageError& e) {
    return e.what();
  }
  const double tile = impl.surfaces->tile_m;
  size_t outside = 0;
  for (const Point& p : *points) {
    const double slack = surface_tile_slack(std::max(std::fabs(p.x), std::fabs(p.y)));
    outside += p.x < x * tile - slack || p.x > (x + 1) * tile + slack || p.y < y * tile - slack ||
               p.y > (y + 1) * tile + slack;
  }
  if (outside) return tile_name(x, y) + ": " + std::to_string(outside) + " points lie outside the tile";
  return {};
}

}  // namespace

void check_surfaces(const MapReader::Impl& impl, size_t max_row_problems, std::vector<std::string>* problems) {
  if (impl.schema_version < 4) return;
  const int64_t tiles = count(impl, "SELECT count(*) FROM surface_tiles");
  if (!impl.surfaces) {
    if (tiles) problems->push_back(std::to_string(tiles) + " surface tiles but no surface_layer row");
    return;
  }
  expect_count("surface tiles", tiles, impl.surfaces->tile_count, problems);
  expect_count("surface points", count(impl, "SELECT coalesce(sum(point_count), 0) FROM surface_tiles"),
               impl.surfaces->point_count, problems);
  expect_count("surface tile bytes", count(impl, "SELECT coalesce(sum(length(points)), 0) FROM surface_tiles"),
               impl.surfaces->stored_bytes, problems);
  Statement st(impl.db.get(), "SELECT tile_x, tile_y, point_count, checksum, points FROM surface_tiles", impl.path);
  size_t bad = 0;
  PointCloud points;
  while (st.step()) {
    const std::string problem = check_tile(impl, st, &points);
    if (!problem.empty() && ++bad <= max_row_problems) problems->push_back(problem);
  }
  if (bad > max_row_problems) {
    problems->push_back("... and " + std::to_string(bad - max_row_problems) + " more bad surface tiles");
  }
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
