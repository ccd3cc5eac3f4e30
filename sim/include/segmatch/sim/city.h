// A simulated city driven twice, in memory: the world, the changed world of the revisit, the
// mapping traversal and the revisit, exactly as generate_dataset() writes them to disk for the
// same DatasetConfig. And the described segments of local clouds along a traversal, labelled
// with the ground-truth instance, as training and tests need them.
#pragma once

#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/training/training.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/local_clouds.h"

#include <memory>

namespace segmatch::sim {

struct City {
  World world;       // as mapped (sequence 00)
  World changed;     // as revisited (sequence 01)
  Traversal first;   // sequence 00
  Traversal second;  // sequence 01
};

City make_city(const DatasetConfig& config);

struct SegmentsAlongConfig {
  LocalCloudSchedule schedule;   // where local clouds are taken
  LocalCloudConfig local_cloud;  // paper III-A: 60 m cylinder, a scan every metre
  SegmentationConfig segmentation;
  bool merge = true;             // views of one object merged as in a map
  SegmentMapConfig segment_map;  // with merge
};

// Segments (world frame, Segment::label = ground truth) of the local clouds along `traversal`
// of `world`, seen by `model`.
Segments segments_along(const World& world, const Traversal& traversal, const LidarModel& model,
                        const SegmentsAlongConfig& config);

// Labelled candidate pairs of one city for training or evaluating the match classifier (paper
// IV-B): the targets are the merged segments of the mapping traversal (a local cloud every
// 5 m), the queries the unmerged segments of the revisit (every 10 m, changed world, other
// lane); each query's k nearest targets in feature space are its candidates, same instance =
// positive, negatives kept at 1:50. `pairs` points into `targets` and `queries`.
struct LabelledCity {
  Segments targets, queries;
  TrainingPairs pairs;
};
std::unique_ptr<LabelledCity> labelled_city(const DatasetConfig& dataset, const LidarModel& model,
                                            SegmentsAlongConfig along, const TrainingPairConfig& pairs);

}  // namespace segmatch::sim
