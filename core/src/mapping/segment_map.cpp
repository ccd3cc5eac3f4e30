#include "segmatch/core/mapping/segment_map.h"

#include <cmath>
#include <stdexcept>

namespace segmatch {

void SegmentMapConfig::validate() const {
  if (!(duplicate_distance_m > 0.0f && duplicate_distance_m < 100.0f))
    throw std::invalid_argument("duplicate_distance_m must be in (0, 100)");
}

SegmentMap::SegmentMap(const SegmentMapConfig& config) : config_(config), grid_(config.duplicate_distance_m) {
  config_.validate();
}

int SegmentMap::find_duplicate(const Eigen::Vector3f& c) const {
  return grid_.nearest(
      c, [&](int i) -> const Eigen::Vector3f& { return segments_[i].centroid; }, [](int) { return true; });
}

std::vector<int> SegmentMap::neighbours_of(int self) const {
  const Eigen::Vector3f& c = segments_[self].centroid;
  std::vector<int> out;
  grid_.for_each_near(c, [&](int i) {
    if (i != self && (segments_[i].centroid - c).norm() < config_.duplicate_distance_m) out.push_back(i);
  });
  return out;
}

void SegmentMap::erase(int index) {
  segments_.erase(segments_.begin() + index);
  // Rare (a replacement that landed on another view): re-index the grid rather than keep
  // back-pointers.
  grid_.clear();
  for (size_t i = 0; i < segments_.size(); ++i) grid_.insert(segments_[i].centroid, static_cast<int>(i));
}

size_t SegmentMap::add(Segments segments) {
  size_t added = 0;
  for (Segment& s : segments) {
    const int dup = find_duplicate(s.centroid);
    if (dup < 0) {
      s.id = next_id_++;
      grid_.insert(s.centroid, static_cast<int>(segments_.size()));
      segments_.push_back(std::move(s));
      ++added;
      continue;
    }
    Segment& old = segments_[dup];
    if (s.points.size() <= old.points.size()) continue;
    // The more complete view wins; it keeps the object's id. Re-file it under its new cell.
    grid_.erase(old.centroid, dup);
    s.id = old.id;
    old = std::move(s);
    grid_.insert(old.centroid, dup);
    if (!config_.resolve_moved_duplicates) continue;
    // The moved centroid may now lie within the duplicate distance of other segments (the
    // others are pairwise far enough apart already): keep the one with more points.
    int self = dup;
    for (std::vector<int> near = neighbours_of(self); !near.empty(); near = neighbours_of(self)) {
      const int other = near.front();
      const Segment& a = segments_[self];
      const Segment& b = segments_[other];
      const bool self_wins = a.points.size() > b.points.size() || (a.points.size() == b.points.size() && a.id < b.id);
      if (!self_wins) {
        erase(self);
        break;
      }
      erase(other);
      if (other < self) --self;
    }
  }
  return added;
}

}  // namespace segmatch
