// Labelled segment pairs from a real recording (paper IV-B on KITTI: labels from the
// ground-truth poses, no object ids). One drive, two disjoint sets of keyframes: the map side
// (targets) from the even keyframes, merged as segmatch-mapbuilder would; the query side from
// local clouds of the odd keyframes, every query_every_m. Both are placed in the world frame
// by the recording's poses, so a candidate's label is its centroid distance
// (label_pairs_by_distance). The drive is cut into stretches of block_m; every
// held_out_every-th stretch is held out for TPR / FPR, the others train the forest (blocks
// rather than one cut, so both sides see every kind of street of the drive).
#pragma once

#include "segmatch/core/training/training.h"
#include "segmatch/io/pipeline_config.h"

#include <memory>
#include <string>

namespace segmatch::eval {

struct RealPairsConfig {
  double map_every_m = 5.0;     // targets: a segmented local cloud every this many metres
  double query_every_m = 10.0;  // queries: likewise, unmerged
  double warmup_m = 30.0;       // no query local cloud before this much driving
  double block_m = 300.0;       // stretch of the drive that goes wholly to one side
  int held_out_every = 3;       // every 3rd stretch is held out (a third of the drive)
  TrainingPairConfig pairs;
};

struct RealPairs {
  Segments targets_train, targets_held_out, queries_train, queries_held_out;
  TrainingPairs train, held_out;  // point into the segments above
  double drive_m = 0.0;
};

// Throws IoError / std::invalid_argument naming the problem (folder, poses, config).
std::unique_ptr<RealPairs> real_pairs(const std::string& folder, const io::PipelineConfig& config,
                                      const RealPairsConfig& rc);

}  // namespace segmatch::eval
