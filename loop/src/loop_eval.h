// Scoring detected loops against ground-truth poses: a loop is true when its relative
// transform agrees with the true relative pose of its two frames; revisits are the processed
// local clouds taken near a place driven long enough before.
#pragma once

#include <segmatch/core/loop/loop_closure.h>

#include <string>
#include <vector>

namespace segmatch::loop {

struct EvalConfig {
  double max_translation_error_m = 1.0;  // a loop is true within 1 m ...
  double max_rotation_error_deg = 3.0;   // ... and 3 deg of the true relative pose
  // A processed local cloud is a revisit when the true sensor position is within this of a
  // frame driven more than min_revisit_gap_m before (along the true path).
  double revisit_radius_m = 5.0;
  double min_revisit_gap_m = 150.0;
  // Precision and recall are also given for these translation-error thresholds (rotation
  // within max_rotation_error_deg): how good the true loops are, and how far off the others.
  std::vector<double> curve_translation_m = {0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 5.0};
};

struct LoopScore {
  double translation_error_m = 0, rotation_error_deg = 0;
  bool correct = false;
};

// A run of consecutive revisit local clouds.
struct RevisitStretch {
  size_t first_frame = 0, last_frame = 0;
  size_t clouds = 0, detected_clouds = 0;  // revisit local clouds, those with a true loop
  double length_m = 0;                     // true path length from first to last frame
  bool detected = false;
  double driven_before_detection_m = 0;  // from first_frame to the first true loop
};

// Precision and recall when a loop counts as true within translation_m (and the rotation
// threshold of the config).
struct ThresholdPoint {
  double translation_m = 0;
  size_t true_loops = 0, detected_revisit_clouds = 0;
  double precision = 0, recall = 0;
};

struct Evaluation {
  std::vector<LoopScore> scores;  // one per loop, same order
  size_t true_loops = 0, false_loops = 0;
  size_t revisit_clouds = 0, detected_revisit_clouds = 0, processed_clouds = 0;
  double precision = 0, recall = 0;  // precision 1 by convention without loops
  std::vector<RevisitStretch> stretches;
  double median_translation_error_m = 0, max_translation_error_m = 0;  // of true loops
  double median_rotation_error_deg = 0, max_rotation_error_deg = 0;
  std::vector<ThresholdPoint> curve;  // one per EvalConfig::curve_translation_m
};

// truth: T_world_sensor per frame of the sequence (indexed by frame). processed: frames where
// a local cloud was matched, increasing. Revisited places are searched among frames
// first_frame.. (the frames the detector was fed). Throws std::invalid_argument when a frame
// has no pose.
Evaluation evaluate(const std::vector<LoopClosure>& loops, const std::vector<size_t>& processed, const Poses& truth,
                    size_t first_frame, const EvalConfig& config);

std::string to_json(const Evaluation& e, const EvalConfig& config);
void print_summary(const Evaluation& e, const EvalConfig& config);

}  // namespace segmatch::loop
