#include <segmatch/storage/lazy_points.h>

namespace segmatch {
namespace storage {

LazyPoints::LazyPoints(std::shared_ptr<const MapReader> reader, size_t cache_points)
    : reader_(std::move(reader)), capacity_(cache_points) {}

void LazyPoints::append(size_t index, PointCloud* out) const {
  Entry points;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto hit = cache_.find(index);
    if (hit != cache_.end()) {
      recent_.splice(recent_.begin(), recent_, hit->second.second);
      points = hit->second.first;
      ++stats_.hits;
    }
  }
  if (!points) {
    // Read outside the lock: two queries missing the same segment at once both read it (the
    // same bytes), which costs less than making every query wait for one read.
    points = std::make_shared<const PointCloud>(reader_->read_points(index));
    std::lock_guard<std::mutex> lock(mutex_);
    ++stats_.reads;
    if (!cache_.count(index) && points->size() <= capacity_) {
      recent_.push_front(index);
      cache_.emplace(index, std::make_pair(points, recent_.begin()));
      stats_.cached_points += points->size();
      while (stats_.cached_points > capacity_) {
        const auto last = cache_.find(recent_.back());
        stats_.cached_points -= last->second.first->size();
        cache_.erase(last);
        recent_.pop_back();
      }
    }
  }
  out->insert(out->end(), points->begin(), points->end());
}

LazyPoints::Stats LazyPoints::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

}  // namespace storage
}  // namespace segmatch
