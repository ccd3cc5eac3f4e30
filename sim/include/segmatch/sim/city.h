// A simulated city driven twice, in memory: the world, the changed world of the revisit, the
// mapping traversal and the revisit, exactly as generate_dataset() writes them to disk for the
// same DatasetConfig. And the described segments of local clouds along a traversal, labelled
// with the ground-truth instance, as training and tests need them.
#pragma once

#include "segmatch/core/localizer.h"
#include "segmatch/core/segment_map.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/local_clouds.h"

namespace segmatch::sim {

struct City {
  World world;      // as mapped (sequence 00)
  World changed;    // as revisited (sequence 01)
  Traversal first;  // sequence 00
  Traversal second; // sequence 01
};

City make_city(const DatasetConfig& config);

struct SegmentsAlongConfig {
  LocalCloudSchedule schedule;        // where local clouds are taken
  LocalCloudConfig local_cloud;       // paper III-A: 60 m cylinder, a scan every metre
  SegmentationConfig segmentation;
  bool merge = true;                  // views of one object merged as in a map
  SegmentMapConfig segment_map;       // with merge
};

// Segments (world frame, Segment::label = ground truth) of the local clouds along `traversal`
// of `world`, seen by `model`.
Segments segments_along(const World& world, const Traversal& traversal, const LidarModel& model,
                        const SegmentsAlongConfig& config);

}  // namespace segmatch::sim
