#include "segmatch/core/mapping/map_correction.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

namespace segmatch {

CorrectedMap correct_segment_map(const Segments& segments, const std::vector<size_t>& frame_of_segment,
                                 const std::function<Pose3d(size_t)>& T_corrected_odom, SegmentMapConfig config) {
  if (segments.size() != frame_of_segment.size())
    throw std::invalid_argument("correct_segment_map: " + std::to_string(segments.size()) + " segments but " +
                                std::to_string(frame_of_segment.size()) + " keyframes");
  Segments moved = segments;
  for (size_t i = 0; i < moved.size(); ++i) {
    const Eigen::Isometry3f T = T_corrected_odom(frame_of_segment[i]).cast<float>();
    for (Point& p : moved[i].points) {
      const Eigen::Vector3f q = T * p.xyz();
      p.x = q.x(), p.y = q.y(), p.z = q.z();
    }
    moved[i].centroid = T * moved[i].centroid;  // descriptors are invariant to a rigid motion
  }
  // Oldest first, so the object keeps its first id when a later view replaces the points.
  std::vector<size_t> order(moved.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return moved[a].id < moved[b].id; });
  Segments ordered;
  ordered.reserve(moved.size());
  for (size_t i : order) ordered.push_back(std::move(moved[i]));
  config.resolve_moved_duplicates = true;
  SegmentMap map(config);
  std::vector<uint64_t> original_id;  // by the id SegmentMap gives each new object (0, 1, ..)
  for (Segment& s : ordered) {
    const uint64_t id = s.id;
    Segments one;
    one.push_back(std::move(s));
    if (map.add(std::move(one)) == 1) original_id.push_back(id);
  }
  CorrectedMap out;
  out.segments = map.segments();
  for (Segment& s : out.segments) s.id = original_id.at(s.id);  // objects keep their ids
  out.merged = segments.size() - out.segments.size();
  return out;
}

}  // namespace segmatch
