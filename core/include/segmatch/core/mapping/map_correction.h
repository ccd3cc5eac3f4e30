// The segment map follows a corrected trajectory (paper IV-D: the pose-graph result "is used
// to update the target segment positions and remove duplicate segments"). Each segment is
// attached to the keyframe it was last seen from and moves with it; once moved, views of the
// same object that drift had kept apart (the old view and the revisit's) coincide and are
// merged, keeping the most complete view as SegmentMap does.
#pragma once

#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/segmentation/segment.h"

#include <cstddef>
#include <functional>
#include <vector>

namespace segmatch {

struct CorrectedMap {
  Segments segments;  // in the corrected frame, duplicates merged
  size_t merged = 0;  // input segments dropped as views of an object already kept
};

// frame_of_segment[i]: the keyframe segments[i] was seen from. T_corrected_odom(frame): maps
// that keyframe's odometry coordinates into the corrected frame, i.e.
// T_corrected_sensor(frame) * T_odom_sensor(frame)^-1. Segments are merged with
// config.duplicate_distance_m and resolve_moved_duplicates on. Throws std::invalid_argument
// when the two lists differ in length.
CorrectedMap correct_segment_map(const Segments& segments, const std::vector<size_t>& frame_of_segment,
                                 const std::function<Pose3d(size_t)>& T_corrected_odom, SegmentMapConfig config);

}  // namespace segmatch
