#include "loop_map.h"
#include "seg_grid.h"

#include <cmath>

namespace segmatch {

LoopSegmentMap::LoopSegmentMap(const SegmentMapConfig& config, const RecencyWindow& window)
    : config_(config), window_(window) {
  config_.validate();
}

uint64_t LoopSegmentMap::cell_of(const Eigen::Vector3f& p) const {
  auto cell = [&](float v) { return static_cast<int64_t>(std::floor(v / config_.duplicate_distance_m)); };
  return detail::pack21(cell(p.z()), cell(p.y()), cell(p.x()));  // x in the low bits
}

int LoopSegmentMap::find_recent_duplicate(const Eigen::Vector3f& c, const Sighting& now) const {
  const float d = config_.duplicate_distance_m;
  int best = -1;
  float best_dist = d;
  for (int dx = -1; dx <= 1; ++dx)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dz = -1; dz <= 1; ++dz) {
        const auto range = grid_.equal_range(cell_of(c + Eigen::Vector3f(dx * d, dy * d, dz * d)));
        for (auto it = range.first; it != range.second; ++it) {
          if (!window_.recent(sightings_[it->second], now)) continue;  // frozen: never merged
          const float dist = (segments_[it->second].centroid - c).norm();
          if (dist < best_dist) {
            best_dist = dist;
            best = it->second;
          }
        }
      }
  return best;
}

void LoopSegmentMap::refile(int index, const Eigen::Vector3f& old_centroid) {
  auto range = grid_.equal_range(cell_of(old_centroid));
  for (auto it = range.first; it != range.second; ++it)
    if (it->second == index) {
      grid_.erase(it);
      break;
    }
  grid_.emplace(cell_of(segments_[index].centroid), index);
}

size_t LoopSegmentMap::add(Segments segments, const Sighting& now) {
  size_t added = 0;
  for (Segment& s : segments) {
    const int dup = find_recent_duplicate(s.centroid, now);
    if (dup < 0) {
      s.id = next_id_++;
      grid_.emplace(cell_of(s.centroid), static_cast<int>(segments_.size()));
      segments_.push_back(std::move(s));
      sightings_.push_back(now);
      view_frames_.push_back(now.frame);
      ++added;
      continue;
    }
    // Seen again: the object stays recent (and is attributed to this local cloud).
    sightings_[dup] = now;
    Segment& old = segments_[dup];
    if (s.points.size() <= old.points.size()) continue;
    const Eigen::Vector3f old_centroid = old.centroid;
    s.id = old.id;
    old = std::move(s);  // the more complete view wins
    view_frames_[dup] = now.frame;
    refile(dup, old_centroid);
  }
  return added;
}

std::vector<int> LoopSegmentMap::eligible(const Sighting& now) const {
  std::vector<int> out;
  for (size_t i = 0; i < segments_.size(); ++i)
    if (!window_.recent(sightings_[i], now)) out.push_back(static_cast<int>(i));
  return out;
}

}  // namespace segmatch
