// Every parameter of the pipeline (local cloud, segmentation, description, matching,
// verification, map merging) as one value, with named per-sensor presets and a JSON form.
//
// The JSON form is what a user writes in a config file and what a map stores as its
// parameters: an object with one sub-object per stage, every key optional (an omitted key keeps
// the preset's value), an unknown key or a value of the wrong type is an error naming it:
//
//   { "preset": "sparse-keyframes",
//     "local_cloud": {"radius_m": 60, "min_travel_between_scans_m": 1, "subsample_leaf_m": 0},
//     "voxel":       {"leaf_m": 0.2, "min_points_per_voxel": 1},
//     "ground":      {"method": "column_variance" | "height_threshold" | "none", ...},
//     "segmenter":   {"type": "euclidean" | "region_growing" | "range_image", "cluster_distance_m": 0.4, ...},
//     "descriptors": {"compute_eigen": true, "compute_esf": true, "esf_samples": 1000, ...},
//     "retrieval":   {"k": 200},
//     "matcher":     {"type": "random_forest" | "l2", "use_shapes": true, "rf_threshold": 0.72, ...},
//     "verification":{"resolution_m": 0.4, "min_inliers": 4, ...},
//     "refine":      {"max_iterations": 30, ...},
//     "localizer":   {"support_radius_m": 1, "min_support": 10, "max_ambiguity": 0.8, ...},
//     "segment_map": {"duplicate_distance_m": 1} }
//
// Field names are the C++ member names of the config structs (see their headers for meaning,
// units and defaults).
#pragma once

#include <segmatch/core/localization/local_cloud.h>
#include <segmatch/core/localization/localizer.h>
#include <segmatch/core/loop/loop_closure.h>
#include <segmatch/core/mapping/segment_map.h>
#include <segmatch/core/mapping/surface_layer.h>
#include <segmatch/core/profile/input_profile.h>

#include <optional>
#include <string>
#include <vector>

namespace segmatch {
namespace io {

struct PipelineConfig {
  PipelineConfig();  // the "kitti-hdl64" preset
  std::string preset = "kitti-hdl64";
  LocalCloudConfig local_cloud;
  LocalizerConfig localizer;
  SegmentMapConfig segment_map;
  SurfaceLayerConfig surfaces;  // the map's surface layer (core/surface_layer.h)
  // With the "auto" profile: what the input measured like (io/auto_profile.h). Stored in the
  // map's parameters as "measured" so that a reader sees why these values were chosen.
  std::optional<InputMeasurements> measured;
  // Throws std::invalid_argument naming the offending field.
  void validate() const;
};

// Sets what follows from the measurements, not a parameter of its own: the elevations the map's
// sensor saw (PlaceRecognitionConfig::map_elevation_*). No measurements: unchanged.
void take_measured_elevations(PipelineConfig& c);

// Presets:
//   "auto"             the default of the tools that read an input: measured and derived by
//                      io::auto_pipeline_config (auto_profile.h); without measurements (a
//                      config file saying "auto") it starts from kitti-hdl64's values;
//   "kitti-hdl64"      the paper's parameters (Table I, section IV-A) for a dense 64-beam
//                      sensor whose raw scans are accumulated (the default);
//   "sparse-keyframes" keyframes already voxel-downsampled by a SLAM front end (~0.2 m point
//                      spacing, e.g. ../shared/data/real): 0.2 m voxels with >= 1 point, 0.4 m
//                      cluster distance, >= 30 points per segment;
//   "livox-keyframes"  sparse-keyframes for a small-FOV short-range sensor (Livox): 30 m
//                      cylinder, >= 20 points, L2 matcher at 3.0 without shapes, 0.7 m
//                      verification resolution, support 4 (meant for loop closure with an
//                      odometry drift bound; tuned on hku-loop1).
// Throws std::invalid_argument listing the known names.
PipelineConfig pipeline_preset(const std::string& name);
std::vector<std::string> pipeline_preset_names();

// Online loop closure from a pipeline config: its stages, plus the loop-closure settings that
// go with its preset (a JSON config holds none). "auto" measured as narrow-fov brings the
// livox-keyframes loop settings stated generically: the recent past and history are 2.5 times
// the measured median range, and the drift bound grows with the distance driven (1.5 % of
// it, at least 0.5 m; 2 deg). "livox-keyframes" brings those it was tuned
// with on hku-loop1: a local cloud every metre, 25 m of recent past and of history, >= 4
// inliers, confidence >= 0.3, odometry drift bound 1 m / 2 deg. The other presets keep
// LoopDetectorConfig's defaults.
LoopDetectorConfig loop_detector_config(const PipelineConfig& p);

// Parses the JSON form above (starting from its "preset", default "kitti-hdl64") and
// validates the result. `origin` names the text in error messages (a file path). Throws IoError
// on malformed JSON, an unknown key, a wrong type or an invalid value.
PipelineConfig parse_pipeline_config(const std::string& json_text, const std::string& origin);

// The parameters stored in a map (MapMetadata::parameters_json, every field written): as
// parse_pipeline_config, except that a parameter added after the map was written takes the
// value that keeps the map answering as it did when built, not today's default:
//   refine.max_segment_points (added with LOCALIZE_SEGMENTS): 0, every point refined.
PipelineConfig parse_map_parameters(const std::string& json_text, const std::string& origin);
// Reads and parses a config file. IoError when missing or unreadable too.
PipelineConfig read_pipeline_config(const std::string& path);
// Every field, pretty-printed; parse_pipeline_config(to_json(c)) == c.
std::string to_json(const PipelineConfig& config);

}  // namespace io
}  // namespace segmatch
