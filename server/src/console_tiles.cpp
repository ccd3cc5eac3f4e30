#include "console_tiles.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace segmatch {
namespace server {
namespace {

// The index's cells: tiles of level 8 (16 m). A finer tile reads one cell and filters; a coarser
// one reads the cells it covers (at most 256 x 256 at level 0, built once per map and cached).
constexpr int kIndexLevel = 8;
constexpr double kIndexCellM = kTileRootM / (1 << kIndexLevel);

uint64_t pack(int64_t x, int64_t y) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(x)) << 32) | static_cast<uint32_t>(y);
}

int64_t cell_of(double v, double size_m) { return static_cast<int64_t>(std::floor(v / size_m)); }

}  // namespace

void TileCache::index(const LoadedMap& map) {
  cells_.clear();
  const Segments& targets = map.localizer->targets();
  for (size_t i = 0; i < targets.size(); ++i) {
    const Eigen::Vector3f& c = targets[i].centroid;
    cells_[pack(cell_of(c.x(), kIndexCellM), cell_of(c.y(), kIndexCellM))].push_back(static_cast<uint32_t>(i));
  }
}

std::string TileCache::build(const LoadedMap& map, int z, int64_t x, int64_t y) const {
  const double size_m = kTileRootM / static_cast<double>(int64_t{1} << z);
  const double x0 = static_cast<double>(x) * size_m, y0 = static_cast<double>(y) * size_m;
  const Segments& targets = map.localizer->targets();
  std::vector<uint32_t> inside;
  auto take = [&](const std::vector<uint32_t>& cell) {
    for (uint32_t i : cell) {
      const Eigen::Vector3f& c = targets[i].centroid;
      if (c.x() >= x0 && c.x() < x0 + size_m && c.y() >= y0 && c.y() < y0 + size_m) inside.push_back(i);
    }
  };
  const int64_t cx0 = cell_of(x0, kIndexCellM), cy0 = cell_of(y0, kIndexCellM);
  const int64_t span = z >= kIndexLevel ? 1 : int64_t{1} << (kIndexLevel - z);
  for (int64_t cx = cx0; cx < cx0 + span; ++cx)
    for (int64_t cy = cy0; cy < cy0 + span; ++cy) {
      const auto it = cells_.find(pack(cx, cy));
      if (it != cells_.end()) take(it->second);
    }
  std::sort(inside.begin(), inside.end());  // map order: the same tile always lists the same sample
  const size_t total = inside.size();
  const size_t stride = (total + kTileMaxSegments - 1) / std::max<size_t>(1, kTileMaxSegments);
  std::string out;
  out.reserve(64 + std::min(total, kTileMaxSegments) * 40);
  char buf[160];
  std::snprintf(buf, sizeof(buf),
                "{\"z\":%d,\"x\":%lld,\"y\":%lld,\"size_m\":%.6g,\"total\":%zu,\"sampled\":%s,\"segments\":[", z,
                static_cast<long long>(x), static_cast<long long>(y), size_m, total, stride > 1 ? "true" : "false");
  out += buf;
  bool first = true;
  for (size_t k = 0; k < total; k += std::max<size_t>(1, stride)) {
    const Segment& s = targets[inside[k]];
    std::snprintf(buf, sizeof(buf), "%s[%llu,%.2f,%.2f,%.2f]", first ? "" : ",", static_cast<unsigned long long>(s.id),
                  s.centroid.x(), s.centroid.y(), s.centroid.z());
    out += buf;
    first = false;
  }
  out += "]}";
  return out;
}

std::string TileCache::tile(const std::shared_ptr<const LoadedMap>& map, int z, int64_t x, int64_t y) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (map.get() != indexed_ || indexed_owner_.expired()) {
    lru_.clear();
    entries_.clear();
    index(*map);
    indexed_ = map.get();
    indexed_owner_ = map;
  }
  const Key key = std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y);
  const auto found = entries_.find(key);
  if (found != entries_.end()) {
    ++counters_.hits;
    lru_.splice(lru_.begin(), lru_, found->second);
    return found->second->second;
  }
  ++counters_.misses;
  lru_.emplace_front(key, build(*map, z, x, y));
  entries_[key] = lru_.begin();
  if (lru_.size() > max_entries_) {
    entries_.erase(lru_.back().first);
    lru_.pop_back();
  }
  return lru_.front().second;
}

TileCache::Counters TileCache::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  Counters c = counters_;
  c.entries = lru_.size();
  return c;
}

}  // namespace server
}  // namespace segmatch
