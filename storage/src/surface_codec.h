// The byte encoding of the surface layer's tiles (schema 4; layout and error bound in
// map_writer.h): which tile a point falls in, a tile's points packed into one BLOB and back,
// and the tile row's XXH64 checksum. Pure functions; no SQLite.
#pragma once

#include <segmatch/core/common/types.h>

#include "bytes.h"

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {
namespace detail {

// floor(v / tile_m) in double, clamped to the int32 range of tile keys (the writer refuses
// points beyond it; a query far away must not overflow the conversion). The writer's split and
// LazySurfaces' query both use this one function, so a point on a border is sought in the tile
// it was stored in.
int64_t surface_tile_index(double v, double tile_m);
// The key of tile (x, y) in one integer, ordered as (x, y).
inline int64_t surface_tile_key(int32_t x, int32_t y) {
  return int64_t{x} * (int64_t{1} << 32) + (int64_t{y} + (int64_t{1} << 31));
}
inline int32_t surface_tile_x(int64_t key) { return static_cast<int32_t>(key >> 32); }
inline int32_t surface_tile_y(int64_t key) { return static_cast<int32_t>((key & 0xFFFFFFFF) - (int64_t{1} << 31)); }
// How far a decoded point may lie outside its tile's square (its quantisation error, float
// rounding included) when its coordinates are at most `magnitude` metres from the origin.
inline double surface_tile_slack(double magnitude) { return 0.006 + 2e-7 * magnitude; }

// A tile's points (x y z; the intensity is not kept) as one BLOB. They decode in the order of
// the voxel grid of leaf_m, not in the given one: a layer's order carries no meaning, and
// neighbours following each other pack smaller.
std::vector<uint8_t> encode_surface_tile(const PointCloud& points, int32_t tile_x, int32_t tile_y, double tile_m,
                                         double leaf_m);
// Empty string on success, else what is wrong with the blob. The points' intensity is 0.
std::string decode_surface_tile(BlobView blob, uint64_t num_points, PointCloud* points);

// Bound to the tile's key and point count, like a segment's points to its row.
uint64_t surface_tile_checksum(int32_t tile_x, int32_t tile_y, uint64_t num_points, BlobView blob);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
