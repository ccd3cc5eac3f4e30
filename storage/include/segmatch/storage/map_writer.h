// Writes a segment map into one SQLite file, all or nothing.
//
// The writer builds the map in "<target>.tmp-<pid>-<n>" next to the target, inside one
// transaction; commit() finishes the transaction, closes and fsyncs the file and renames it
// over the target (then fsyncs the folder). A writer destroyed before commit() deletes its
// temporary file, and a crashed or killed process leaves at most that temporary file behind:
// the target path never holds a half-written map, and a map it held before stays intact.
// A MapWriter is used from one thread at a time.
//
// File layout (schema version 4; application_id 'SgMp', user_version = schema version; 1 KiB
// pages):
//   map_info       one row: metadata, the parameters JSON, descriptor sizes and row counts
//   segments       one row per segment (rows 1..N in insertion order): id, keyframe, label,
//                  centroid, axis-aligned bounding box of the points, point count, two BLOBs
//                  (eigen: 7 float32; esf: 640 u16 of one power-of-two scale, sparse, see
//                  packed_blobs.h; both NULL
//                  when not described) and an XXH64 checksum over the row
//   segment_points one row per segment, same row number: the points (see below, packed) and
//                  their own XXH64 checksum, so that the rest of a segment is read without
//                  touching its points
//   segment_rtree  R*Tree over the centroids (SQLite rtree module), for segments_near()
//   trajectory     one row per keyframe: index, time, T_map_sensor as 12 doubles
//                  (rotation row-major r00..r22, then tx ty tz), exact
//   classifier     at most one row: format string, opaque bytes (zstd-packed), checksum of
//                  the unpacked bytes
//   surface_layer  at most one row (none: the map has no surface layer): leaf_m, tile_m, and
//                  the tile count, point count and BLOB bytes of surface_tiles (schema 4)
//   surface_tiles  one row per non-empty tile, primary key (tile_x, tile_y) = floor(x / tile_m),
//                  floor(y / tile_m) in double: point count, the points (below) and an XXH64
//                  checksum over the key, the count and the BLOB (schema 4)
// All numbers in BLOBs are little-endian.
//
// Point precision. Each segment's points are stored as four int16 per point (8 bytes):
// x, y, z and intensity each decode to offset + q * scale, with the offsets at the centre of
// the segment's range (a 36-byte header holds offsets and scales):
//   - x y z in 2 mm steps when every point lies within 65 m of the box centre (error <= 1 mm
//     per axis), else in 1 cm steps when within 327 m (error <= 5 mm per axis),
//   - intensity in 65534 steps between the segment's min and max (error <= (max - min) /
//     131068; exact when all are equal),
//   - the exact float32 points (16 bytes a point) when a segment is wider still or holds a
//     non-finite value.
// Decoding runs in float, so add float rounding: about 0.01 mm for coordinates below 100 m,
// 0.5 mm at 10 km.
// Surface tiles keep x y z only (the points decode with intensity 0), each axis as an int16 q
// of 1 cm steps from an offset: x y from the tile's centre, z from the middle of its heights,
// each moved onto the voxel grid of leaf_m (anchored at 0). The BLOB: a byte 1, the offsets
// (3 float64), the voxel size in steps (u16, v), then a zstd frame of 12 byte planes: q = cell *
// v + rest (0 <= rest < v), the points sorted by cell (y, x, z), the cells' deltas along them
// (zigzag) and the rests, each as x low, x high, y low... (~1.5 bytes a point on the bench's
// ground and facades at 0.25 m). Error <= 5 mm per axis, plus one float rounding of the
// decoded coordinate (<= 0.004 mm below 128 m, <= 0.5 mm below 16 km), so a point may decode
// up to that far outside its tile. A tile wider than 655 m or with heights spread over more is
// stored exactly instead (a byte 2, then x y z float32 in 12 byte planes, zstd). The points
// are stored as given: the caller thins them to leaf_m (recorded in surface_layer).
// ESF bins move by at most 2^-16 of the segment's largest bin (u16 at a power-of-two scale,
// as LOCALIZE_SEGMENTS sends them; schema 3). Everything else (ids, centroids, eigen, labels,
// keyframes, poses, times, metadata, classifier bytes) round-trips exactly.
// Schema 2 stores the same x y z and descriptor bytes as schema 1 did, losslessly packed with
// zstd (x y z delta-coded per axis and split into byte planes: ~2.9 bytes a point instead of
// 8), and does not keep the intensity of int16 points (nothing in localization reads it; it
// decodes to the middle of the segment's range). Schema 1 kept the points as a third BLOB of
// the segments row, unpacked, in 64 KiB pages. Schema 3 stores the ESF quantised instead of
// packed: decoding zstd frames was most of opening a city map. Schema 1 and 2 maps are still
// read; upgrade_map() rewrites them. Schema 4 adds the surface layer; a map of schema 1 to 3
// has none (nor does one upgraded from them: the file holds no scans to make one from).
#pragma once

#include <segmatch/core/segmentation/segment.h>
#include <segmatch/storage/map_types.h>

#include <memory>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {

class MapWriter {
 public:
  // Refuses (StorageError, before touching anything) when `path` exists and overwrite is
  // false, or when its folder does not exist. metadata.eigen_dims / esf_dims must match this
  // build (std::invalid_argument otherwise).
  static MapWriter create(const std::string& path, const MapMetadata& metadata, bool overwrite);

  MapWriter(MapWriter&&) noexcept;
  MapWriter& operator=(MapWriter&&) noexcept;
  MapWriter(const MapWriter&) = delete;
  MapWriter& operator=(const MapWriter&) = delete;
  // Without commit(): rolls back and deletes the temporary file.
  ~MapWriter();

  // Appends segments (may be called many times). keyframe_of_segment is empty (keyframes
  // unknown) or holds one keyframe index per segment. Every segment needs a finite centroid.
  void add_segments(const Segments& segments, const std::vector<uint32_t>& keyframe_of_segment);
  // Replaces the trajectory. Keyframe indices must be unique.
  void set_trajectory(const std::vector<Keyframe>& keyframes);
  // Replaces the classifier model.
  void set_classifier(const ClassifierBlob& classifier);
  // The map's surface layer: `points_map` (map frame, thinned to leaf_m by the caller) split
  // into tiles of tile_m x tile_m metres, stored as above. Replaces a layer set before; a map
  // written without calling it has no layer. An empty cloud makes a layer of no tiles.
  // std::invalid_argument naming the problem: a non-finite point, leaf_m or tile_m not finite
  // and > 0, a point whose tile index does not fit int32.
  void set_surfaces(const PointCloud& points_map, float leaf_m, float tile_m);
  // Makes the map visible at the target path. The writer is finished afterwards.
  void commit();

  const std::string& path() const;            // the target
  const std::string& temporary_path() const;  // where the map is being built

 private:
  friend int upgrade_map(const std::string& old_path, const std::string& new_path, bool overwrite);
  struct Impl;
  explicit MapWriter(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Rewrites the map at old_path (any schema this build reads) in this build's schema at
// new_path, all or nothing like a build. Point coordinates and eigen features are the same
// bytes repacked, not re-quantised, so they decode to the same floats (the intensity of int16
// points is not kept, as from schema 2 on); ESF is quantised as a schema-3 build stores it
// (a schema-3 ESF quantises to itself). Every row's checksum
// and BLOBs are verified first (a damaged map is refused, naming the row). The new map has no
// surface layer when the old one had none (every map before schema 4): only rebuilding the map
// from its traversal makes one. Returns the old schema version; StorageError when the map
// already has this build's schema.
int upgrade_map(const std::string& old_path, const std::string& new_path, bool overwrite);

}  // namespace storage
}  // namespace segmatch
