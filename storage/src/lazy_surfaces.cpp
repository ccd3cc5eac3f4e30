#include <segmatch/storage/lazy_surfaces.h>

#include "surface_codec.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace segmatch {
namespace storage {

using namespace detail;

namespace {

// Horizontal distance from c to the interval [lo, hi] (0 inside).
double gap(double c, double lo, double hi) { return std::max({lo - c, 0.0, c - hi}); }

}  // namespace

LazySurfaces::LazySurfaces(std::shared_ptr<const MapReader> reader, size_t cache_points)
    : reader_(std::move(reader)), capacity_(cache_points) {
  const std::optional<SurfaceLayer> layer = reader_->surfaces();
  if (!layer) throw std::invalid_argument("LazySurfaces: " + reader_->path() + " has no surface layer");
  layer_ = *layer;
  for (const auto& [x, y] : reader_->surface_tile_keys()) keys_.insert(surface_tile_key(x, y));
}

PointCloud LazySurfaces::near(const Eigen::Vector3d& center, double radius_m) const {
  if (!center.allFinite() || !std::isfinite(radius_m)) {
    throw std::invalid_argument("LazySurfaces::near: non-finite center or radius");
  }
  PointCloud out;
  if (radius_m < 0.0) return out;
  const double cx = center.x(), cy = center.y(), size = layer_.tile_m;
  // Tiles are chosen by their square widened by the quantisation error (a point may decode just
  // outside its tile); the points are then cropped exactly.
  const double reach = radius_m + surface_tile_slack(std::max(std::fabs(cx), std::fabs(cy)) + radius_m);
  const int64_t x0 = surface_tile_index(cx - reach, size), x1 = surface_tile_index(cx + reach, size);
  const int64_t y0 = surface_tile_index(cy - reach, size), y1 = surface_tile_index(cy + reach, size);
  const auto touches = [&](int64_t x, int64_t y) {
    const double dx = gap(cx, x * size, (x + 1) * size), dy = gap(cy, y * size, (y + 1) * size);
    return dx * dx + dy * dy <= reach * reach;
  };
  std::vector<int64_t> tiles;
  if (double(x1 - x0 + 1) * double(y1 - y0 + 1) <= double(keys_.size())) {
    for (int64_t x = x0; x <= x1; ++x)
      for (int64_t y = y0; y <= y1; ++y) {
        const int64_t key = surface_tile_key(int32_t(x), int32_t(y));
        if (keys_.count(key) && touches(x, y)) tiles.push_back(key);
      }
  } else {  // a disc wider than the stored tiles: look at each of them instead of each place
    for (int64_t key : keys_) {
      const int64_t x = surface_tile_x(key), y = surface_tile_y(key);
      if (x >= x0 && x <= x1 && y >= y0 && y <= y1 && touches(x, y)) tiles.push_back(key);
    }
    std::sort(tiles.begin(), tiles.end());
  }
  const double r2 = radius_m * radius_m;
  std::vector<Entry> entries;
  entries.reserve(tiles.size());
  size_t most = 0;
  for (int64_t key : tiles) {
    entries.push_back(tile(key));
    most += entries.back()->size();
  }
  out.reserve(most);
  for (const Entry& points : entries) {
    for (const Point& p : *points) {
      const double dx = double(p.x) - cx, dy = double(p.y) - cy;
      if (dx * dx + dy * dy <= r2) out.push_back(p);
    }
  }
  return out;
}

LazySurfaces::Entry LazySurfaces::tile(int64_t key) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto hit = cache_.find(key);
    if (hit != cache_.end()) {
      recent_.splice(recent_.begin(), recent_, hit->second.second);
      ++stats_.hits;
      return hit->second.first;
    }
  }
  // Read outside the lock, as LazyPoints does: two queries missing the same tile at once both
  // read it, which costs less than making every query wait for one read.
  Entry points = std::make_shared<const PointCloud>(reader_->surface_tile(surface_tile_x(key), surface_tile_y(key)));
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.reads;
  if (!cache_.count(key) && points->size() <= capacity_) {
    recent_.push_front(key);
    cache_.emplace(key, std::make_pair(points, recent_.begin()));
    stats_.cached_points += points->size();
    while (stats_.cached_points > capacity_) {
      const auto last = cache_.find(recent_.back());
      stats_.cached_points -= last->second.first->size();
      cache_.erase(last);
      recent_.pop_back();
    }
  }
  return points;
}

LazySurfaces::Stats LazySurfaces::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

std::shared_ptr<const MapSurfaces> make_lazy_surfaces(std::shared_ptr<const MapReader> reader, size_t cache_points) {
  if (!reader || !reader->surfaces()) return nullptr;
  return std::make_shared<const LazySurfaces>(std::move(reader), cache_points);
}

}  // namespace storage
}  // namespace segmatch
