// A map's segment points read from its file when refinement asks for them (core's
// TargetPoints), with a bounded least-recently-used cache shared by every query: a server then
// holds in memory only what retrieval, classification and verification need.
#pragma once

#include <segmatch/core/localization/localizer.h>
#include <segmatch/storage/map_reader.h>

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <unordered_map>

namespace segmatch {
namespace storage {

class LazyPoints : public TargetPoints {
 public:
  // Up to cache_points points stay cached (16 bytes each: the default is 32 MB).
  explicit LazyPoints(std::shared_ptr<const MapReader> reader, size_t cache_points = 2'000'000);

  // Thread-safe. Throws StorageError naming the segment's row when its points are damaged.
  void append(size_t index, PointCloud* out) const override;

  struct Stats {
    uint64_t reads = 0, hits = 0;  // segments read from the file, served from the cache
    size_t cached_points = 0;
  };
  Stats stats() const;

 private:
  using Entry = std::shared_ptr<const PointCloud>;
  std::shared_ptr<const MapReader> reader_;
  size_t capacity_;
  mutable std::mutex mutex_;
  mutable std::list<size_t> recent_;  // most recent first
  mutable std::unordered_map<size_t, std::pair<Entry, std::list<size_t>::iterator>> cache_;
  mutable Stats stats_;
};

}  // namespace storage
}  // namespace segmatch
