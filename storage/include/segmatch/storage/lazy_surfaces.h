// A map's surface layer read from its file tile by tile when registration asks for the
// surfaces near a place (core's MapSurfaces), with a bounded least-recently-used cache of tiles
// shared by every query, as LazyPoints does for segment points.
#pragma once

#include <segmatch/core/localization/localizer.h>
#include <segmatch/storage/map_reader.h>

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <unordered_set>

namespace segmatch {
namespace storage {

class LazySurfaces : public MapSurfaces {
 public:
  // Up to cache_points points stay cached (16 bytes each: the default is 64 MB). Reads the
  // tiles' keys (not their points); std::invalid_argument when the map has no surface layer.
  explicit LazySurfaces(std::shared_ptr<const MapReader> reader, size_t cache_points = 4'000'000);

  // The points within radius_m of center horizontally ((x - cx)^2 + (y - cy)^2 <= r^2 in
  // double, on the decoded points), tile by tile in key order. Thread-safe. Throws StorageError
  // naming the tile when one is damaged, std::invalid_argument for a non-finite center or
  // radius; a negative radius gives no points.
  PointCloud near(const Eigen::Vector3d& center, double radius_m) const override;

  const SurfaceLayer& layer() const { return layer_; }

  struct Stats {
    uint64_t reads = 0, hits = 0;  // tiles read from the file, served from the cache
    size_t cached_points = 0;
  };
  Stats stats() const;

 private:
  using Entry = std::shared_ptr<const PointCloud>;
  Entry tile(int64_t key) const;

  std::shared_ptr<const MapReader> reader_;
  SurfaceLayer layer_;
  std::unordered_set<int64_t> keys_;  // the stored tiles: no file read for an empty one
  size_t capacity_;
  mutable std::mutex mutex_;
  mutable std::list<int64_t> recent_;  // most recent first
  mutable std::unordered_map<int64_t, std::pair<Entry, std::list<int64_t>::iterator>> cache_;
  mutable Stats stats_;
};

// A LazySurfaces over the reader's layer, or null when the map has none (the localizer then
// registers onto segment points alone).
std::shared_ptr<const MapSurfaces> make_lazy_surfaces(std::shared_ptr<const MapReader> reader,
                                                      size_t cache_points = 4'000'000);

}  // namespace storage
}  // namespace segmatch
