// Reads a segment map written by MapWriter.
//
// open() refuses, with a StorageError naming the file and the problem, a missing file, a file
// that is not SQLite, an SQLite database of another application, a schema version this build
// cannot read (newer, or older than kOldestReadableSchemaVersion), a truncated file, and a
// database whose tables are missing or unreadable. Corruption further inside the file is
// found when the damaged part is read: SQLite's page checks and the per-row checksums turn it
// into a StorageError ("... is corrupted: ..."); check_integrity() inspects everything.
//
// The file is opened read-only (SQLITE_OPEN_READONLY): a reader never modifies it, needs no
// write permission and any number of processes may read one map at once. Threads: the
// methods are const and may be called from several threads on one MapReader (SQLite
// serialises them on the reader's connection); for parallel throughput give each thread its
// own MapReader.
#pragma once

#include <segmatch/core/segmentation/segment.h>
#include <segmatch/storage/map_types.h>

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace segmatch {
namespace storage {

class MapReader {
 public:
  static MapReader open(const std::string& path);

  MapReader(MapReader&&) noexcept;
  MapReader& operator=(MapReader&&) noexcept;
  MapReader(const MapReader&) = delete;
  MapReader& operator=(const MapReader&) = delete;
  ~MapReader();

  const std::string& path() const;
  const MapMetadata& metadata() const;
  int schema_version() const;

  // All segments in the order they were added. When keyframe_of_segment is given it receives
  // one keyframe index per segment (kNoKeyframe when unknown).
  Segments load_segments(std::vector<uint32_t>* keyframe_of_segment = nullptr) const;
  // The same without their points: what retrieval, classification and verification need. A
  // schema-2 map reads no page of its points for it (schema 1 keeps them in the same rows).
  Segments load_segments_without_points(std::vector<uint32_t>* keyframe_of_segment = nullptr) const;
  // The points of the segment at `index` in load order, checked against their checksum
  // (StorageError naming the row otherwise).
  PointCloud read_points(size_t index) const;
  // Stops memory-mapping the file (open() maps it, which makes full loads fast): later reads go
  // through SQLite's small page cache, so a reader kept open to read a few segments per query
  // does not keep the pages of everything read so far resident.
  void stop_mapping() const;
  // The segments whose centroid c satisfies (c - center).squaredNorm() <= radius_m^2 (float
  // arithmetic), in the order they were added; reads only those rows (R*Tree lookup).
  Segments segments_near(const Eigen::Vector3f& center, float radius_m,
                         std::vector<uint32_t>* keyframe_of_segment = nullptr) const;
  // Keyframes by increasing index.
  std::vector<Keyframe> trajectory() const;
  std::optional<ClassifierBlob> classifier() const;
  MapStats stats() const;

  // The surface layer (map_writer.h): nullopt for maps before schema 4 and for maps written
  // without set_surfaces(). Read at open(): free to call.
  std::optional<SurfaceLayer> surfaces() const;
  // The points of tile (tile_x, tile_y): x in [tile_x, tile_x + 1) * tile_m, y likewise (as
  // stored: within the quantisation error of map_writer.h), intensity 0; empty when there is
  // no such tile or no layer. Checked against the tile's checksum (StorageError naming the tile
  // and the file otherwise). Thread-safe as read_points().
  PointCloud surface_tile(int32_t tile_x, int32_t tile_y) const;
  // The keys (tile_x, tile_y) of every stored tile, ordered by x then y; empty without a layer.
  // Reads the primary key's index only, no tile's points.
  std::vector<std::pair<int32_t, int32_t>> surface_tile_keys() const;

  // Full check: PRAGMA integrity_check, row counts against map_info, the R*Tree against the
  // centroids, every checksum and point BLOB, keyframe references, the surface layer's counts,
  // tile checksums and points. Empty = healthy; reads the whole file, so it takes about as long
  // as load_segments().
  std::vector<std::string> check_integrity() const;

  struct Impl;  // opaque; named here so the library's internal files can share it

 private:
  friend int upgrade_map(const std::string& old_path, const std::string& new_path, bool overwrite);
  explicit MapReader(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace storage
}  // namespace segmatch
