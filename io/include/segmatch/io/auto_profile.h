// The `auto` profile: measure the input, derive every parameter from the
// measurements. Named presets stay as explicit overrides.
//
// Rules (each cites what it was chosen on; docs/parameters.md holds the figures):
//   dense-spinning  (raw scans of a 360-degree sensor: KITTI, the simulator)  -> kitti-hdl64,
//                   the paper's Table I values, unchanged;
//   sparse-spinning (keyframes a SLAM front end voxelized, 360 degrees: riverside02) -> voxel
//                   leaf = the measured point spacing, >= 1 point, cluster distance = 2 leaves,
//                   segment size scaled by the leaf, a keyframe is never skipped when keyframes
//                   are metres apart; matching looser than the paper's (RF 0.6, k 500) and a
//                   stricter support (14): chosen on riverside02 keyframes 0-140, reported on
//                   141-280 apart;
//   narrow-fov      (Livox Avia class: ~70 degrees, short range) -> sparse-spinning's
//                   segmentation, a cylinder of three times the measured median range,
//                   the L2 matcher at 3.0 without shapes, 0.7 m verification, support 4;
//                   chosen on hku-loop1, checked on hku-mb.
#pragma once

#include <segmatch/core/profile/input_profile.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/sequence.h>

#include <string>

namespace segmatch {
namespace io {

// Measures scans first..last (inclusive, clipped) every `stride` of a sequence: a sample of
// them is read (scans_to_measure), the poses of all of them are used.
InputMeasurements measure_sequence(const Sequence& sequence, size_t first = 0, size_t last = SIZE_MAX,
                                   size_t stride = 1, const InputProfileConfig& config = {});

// The pipeline for inputs that measure like this; preset "auto", `measured` set.
PipelineConfig auto_pipeline_config(const InputMeasurements& measured);

// What was measured and chosen, for a person (several lines, no trailing newline).
std::string describe_profile(const PipelineConfig& config);
// Its last line alone: the parameters chosen ("chose (auto): 60 m cylinder, ...").
std::string describe_choice(const PipelineConfig& config);

}  // namespace io
}  // namespace segmatch
