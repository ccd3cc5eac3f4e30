#include "loop/loop_map.h"

#include <cmath>

namespace segmatch {

LoopSegmentMap::LoopSegmentMap(const SegmentMapConfig& config, const RecencyWindow& window)
    : config_(config), window_(window), grid_(config.duplicate_distance_m) {
  config_.validate();
}

int LoopSegmentMap::find_recent_duplicate(const Eigen::Vector3f& c, const Sighting& now) const {
  return grid_.nearest(
      c, [&](int i) -> const Eigen::Vector3f& { return segments_[i].centroid; },
      [&](int i) { return window_.recent(sightings_[i], now); });  // frozen: never merged
}

void LoopSegmentMap::refile(int index, const Eigen::Vector3f& old_centroid) {
  grid_.erase(old_centroid, index);
  grid_.insert(segments_[index].centroid, index);
}

size_t LoopSegmentMap::add(Segments segments, const Sighting& now) {
  size_t added = 0;
  for (Segment& s : segments) {
    const int dup = find_recent_duplicate(s.centroid, now);
    if (dup < 0) {
      s.id = next_id_++;
      grid_.insert(s.centroid, static_cast<int>(segments_.size()));
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
