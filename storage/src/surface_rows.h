// The surface layer's rows (schema 4, see map_writer.h): written by MapWriter::set_surfaces,
// read by MapReader::surfaces() / surface_tile(), inspected by check_integrity().
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/storage/map_types.h>

#include "reader_impl.h"
#include "sqlite_util.h"

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

// std::invalid_argument naming the problem: a non-finite point, leaf_m or tile_m not finite and
// > 0, a point beyond the int32 tile grid.
void validate_surfaces(const PointCloud& points, float leaf_m, float tile_m);
// Replaces the layer: one surface_tiles row per non-empty tile, and the surface_layer row.
void write_surfaces(sqlite3* db, const std::string& path, const PointCloud& points, float leaf_m, float tile_m);

// The surface_layer row; nullopt before schema 4 or when the map was written without a layer.
std::optional<SurfaceLayer> read_surface_layer(sqlite3* db, const std::string& path, int schema_version);

// Binds tile_x, tile_y; columns: point_count, checksum, points.
extern const char* const kSelectSurfaceTileSql;
// Checks the row's checksum and decodes its points, reading columns first..first + 2 as
// kSelectSurfaceTileSql orders them; StorageError ("... is corrupted: surface tile (x, y): ...").
void decode_surface_row(const Statement& st, int first, int32_t tile_x, int32_t tile_y, const std::string& path,
                        PointCloud* points);
// The stored tiles' keys, ordered by x then y.
std::vector<std::pair<int32_t, int32_t>> read_surface_tile_keys(const MapReader::Impl& impl);

// check_integrity()'s part: the layer row against the tiles, every tile's checksum and points.
void check_surfaces(const MapReader::Impl& impl, size_t max_row_problems, std::vector<std::string>* problems);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
