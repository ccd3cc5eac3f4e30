// The map's segments in square tiles of the map frame, for the operator's page (docs/console.md,
// "Tiles"): level z holds tiles of kTileRootM / 2^z metres; tile (x, y) covers
// [x s, (x + 1) s) x [y s, (y + 1) s). A tile lists at most kTileMaxSegments segments (an
// even sample of its segments beyond that), so a coarse view of a city stays small; the page
// asks for finer tiles as it zooms in. Each tile's JSON is built once per served map and kept
// in a bounded LRU cache: a page that pans back and forth costs the server nothing.
#pragma once

#include "segmatch/server/map_service.h"

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

namespace segmatch {
namespace server {

constexpr double kTileRootM = 4096.0;
constexpr int kTileMaxLevel = 12;
constexpr size_t kTileMaxSegments = 4000;

class TileCache {
 public:
  explicit TileCache(size_t max_entries) : max_entries_(max_entries) {}
  // The JSON of tile (z, x, y) of `map` (z within [0, kTileMaxLevel]; the caller checks). A map
  // other than the last one asked about (a reload) drops the cache and the index.
  std::string tile(const std::shared_ptr<const LoadedMap>& map, int z, int64_t x, int64_t y);
  struct Counters {
    uint64_t hits = 0, misses = 0;
    size_t entries = 0;
  };
  Counters counters() const;

 private:
  std::string build(const LoadedMap& map, int z, int64_t x, int64_t y) const;
  void index(const LoadedMap& map);

  mutable std::mutex mutex_;
  size_t max_entries_;
  const LoadedMap* indexed_ = nullptr;  // compared only, never dereferenced after a reload
  std::weak_ptr<const LoadedMap> indexed_owner_;
  // Segment indices by kIndexCellM cell (packed x, y), for tiles of any level.
  std::unordered_map<uint64_t, std::vector<uint32_t>> cells_;
  using Key = std::string;                      // "z/x/y"
  std::list<std::pair<Key, std::string>> lru_;  // most recent first
  std::unordered_map<Key, std::list<std::pair<Key, std::string>>::iterator> entries_;
  Counters counters_;
};

}  // namespace server
}  // namespace segmatch
