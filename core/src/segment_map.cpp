#include "segmatch/core/segment_map.h"
#include "seg_grid.h"

#include <cmath>
#include <stdexcept>

namespace segmatch {

void SegmentMapConfig::validate() const {
  if (!(duplicate_distance_m > 0.0f && duplicate_distance_m < 100.0f))
    throw std::invalid_argument("duplicate_distance_m must be in (0, 100)");
}

SegmentMap::SegmentMap(const SegmentMapConfig& config) : config_(config) { config_.validate(); }

SegmentMap::CellKey SegmentMap::cell_of(const Eigen::Vector3f& p) const {
  auto cell = [&](float v) { return static_cast<int64_t>(std::floor(v / config_.duplicate_distance_m)); };
  return detail::pack21(cell(p.z()), cell(p.y()), cell(p.x()));  // x in the low bits
}

int SegmentMap::find_duplicate(const Eigen::Vector3f& c) const {
  const float d = config_.duplicate_distance_m;
  int best = -1;
  float best_dist = d;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const auto range = grid_.equal_range(cell_of(c + Eigen::Vector3f(dx * d, dy * d, dz * d)));
        for (auto it = range.first; it != range.second; ++it) {
          const float dist = (segments_[it->second].centroid - c).norm();
          if (dist < best_dist) {
            best_dist = dist;
            best = it->second;
          }
        }
      }
  return best;
}

std::vector<int> SegmentMap::neighbours_of(int self) const {
  const float d = config_.duplicate_distance_m;
  const Eigen::Vector3f& c = segments_[self].centroid;
  std::vector<int> out;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const auto range = grid_.equal_range(cell_of(c + Eigen::Vector3f(dx * d, dy * d, dz * d)));
        for (auto it = range.first; it != range.second; ++it)
          if (it->second != self && (segments_[it->second].centroid - c).norm() < d) out.push_back(it->second);
      }
  return out;
}

void SegmentMap::erase(int index) {
  segments_.erase(segments_.begin() + index);
  // Rare (a replacement that landed on another view): re-index the grid rather than keep
  // back-pointers.
  grid_.clear();
  for (size_t i = 0; i < segments_.size(); ++i) grid_.emplace(cell_of(segments_[i].centroid), static_cast<int>(i));
}

size_t SegmentMap::add(Segments segments) {
  size_t added = 0;
  for (Segment& s : segments) {
    const int dup = find_duplicate(s.centroid);
    if (dup < 0) {
      s.id = next_id_++;
      grid_.emplace(cell_of(s.centroid), static_cast<int>(segments_.size()));
      segments_.push_back(std::move(s));
      ++added;
      continue;
    }
    Segment& old = segments_[dup];
    if (s.points.size() <= old.points.size()) continue;
    // The more complete view wins; it keeps the object's id. Re-file it under its new cell.
    auto range = grid_.equal_range(cell_of(old.centroid));
    for (auto it = range.first; it != range.second; ++it)
      if (it->second == dup) {
        grid_.erase(it);
        break;
      }
    s.id = old.id;
    old = std::move(s);
    grid_.emplace(cell_of(old.centroid), dup);
    if (!config_.resolve_moved_duplicates) continue;
    // The moved centroid may now lie within the duplicate distance of other segments (the
    // others are pairwise far enough apart already): keep the one with more points.
    int self = dup;
    for (std::vector<int> near = neighbours_of(self); !near.empty(); near = neighbours_of(self)) {
      const int other = near.front();
      const Segment& a = segments_[self];
      const Segment& b = segments_[other];
      const bool self_wins =
          a.points.size() > b.points.size() || (a.points.size() == b.points.size() && a.id < b.id);
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
