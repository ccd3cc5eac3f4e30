#include "segmatch/io/pipeline_config.h"

#include "segmatch/io/error.h"

#include <nlohmann/json.hpp>

#include <charconv>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <utility>

namespace segmatch {
namespace io {
namespace {

using nlohmann::json;

// Enum <-> the names a user writes.
template <class E>
using EnumNames = std::vector<std::pair<E, const char*>>;
const EnumNames<GroundRemoval>& names(GroundRemoval*) {
  static const EnumNames<GroundRemoval> n = {{GroundRemoval::kNone, "none"},
                                             {GroundRemoval::kHeightThreshold, "height_threshold"},
                                             {GroundRemoval::kColumnVariance, "column_variance"}};
  return n;
}
const EnumNames<SegmenterType>& names(SegmenterType*) {
  static const EnumNames<SegmenterType> n = {{SegmenterType::kEuclidean, "euclidean"},
                                             {SegmenterType::kRegionGrowing, "region_growing"},
                                             {SegmenterType::kRangeImage, "range_image"}};
  return n;
}
const EnumNames<MatcherType>& names(MatcherType*) {
  static const EnumNames<MatcherType> n = {{MatcherType::kL2, "l2"}, {MatcherType::kRandomForest, "random_forest"}};
  return n;
}

// The local cloud, its segmentation and description (the paper's III-A and III-B).
template <class V>
void visit_segmentation(V& v, PipelineConfig& c) {
  SegmentationConfig& s = c.localizer.segmentation;
  v.section("local_cloud");
  v("radius_m", c.local_cloud.radius_m);
  v("min_travel_between_scans_m", c.local_cloud.min_travel_between_scans_m);
  v("subsample_leaf_m", c.local_cloud.subsample_leaf_m);
  v("max_scan_age_m", c.local_cloud.max_scan_age_m);
  v.section("voxel");
  v("leaf_m", s.voxel.leaf_m);
  v("min_points_per_voxel", s.voxel.min_points_per_voxel);
  v.section("ground");
  v("method", s.ground.method);
  v("height_above_ground_m", s.ground.height_above_ground_m);
  v("sensor_height_m", s.ground.sensor_height_m);
  v("column_size_m", s.ground.column_size_m);
  v("max_column_spread_m", s.ground.max_column_spread_m);
  v("max_column_stddev_m", s.ground.max_column_stddev_m);
  v("envelope_tile_m", s.ground.envelope_tile_m);
  v("seed_tolerance_m", s.ground.seed_tolerance_m);
  v("max_step_m", s.ground.max_step_m);
  v("ground_margin_m", s.ground.ground_margin_m);
  v("max_search_rings", s.ground.max_search_rings);
  v.section("segmenter");
  v("type", s.segmenter.type);
  v("cluster_distance_m", s.segmenter.cluster_distance_m);
  v("min_points", s.segmenter.min_points);
  v("max_points", s.segmenter.max_points);
  v("normal_radius_m", s.segmenter.normal_radius_m);
  v("max_normal_angle_deg", s.segmenter.max_normal_angle_deg);
  v("max_curvature", s.segmenter.max_curvature);
  v("min_normal_neighbours", s.segmenter.min_normal_neighbours);
  v("range_image_beta_deg", s.segmenter.range_image_beta_deg);
  v("range_image_rows", s.segmenter.range_image_rows);
  v("range_image_azimuth_step_deg", s.segmenter.range_image_azimuth_step_deg);
  v.section("descriptors");
  v("compute_eigen", s.descriptors.compute_eigen);
  v("compute_esf", s.descriptors.compute_esf);
  v("esf_samples", s.descriptors.esf_samples);
  v("esf_seed", s.descriptors.esf_seed);
}

// Retrieval and matching (III-C), geometric verification (III-D) and the pose refinement.
template <class V>
void visit_matching(V& v, PipelineConfig& c) {
  LocalizerConfig& l = c.localizer;
  v.section("retrieval");
  v("k", l.retrieval.k);
  v.section("matcher");
  v("type", l.matcher.type);
  v("use_shapes", l.matcher.use_shapes);
  v("l2_threshold", l.matcher.l2_threshold);
  v("rf_threshold", l.matcher.rf_threshold);
  v("rf_trees", l.matcher.rf_trees);
  v("rf_max_depth", l.matcher.rf_max_depth);
  v("rf_min_samples", l.matcher.rf_min_samples);
  v.section("verification");
  v("resolution_m", l.verification.resolution_m);
  v("min_inliers", l.verification.min_inliers);
  v("max_iterations", l.verification.max_iterations);
  v("seed", l.verification.seed);
  v("max_hypotheses", l.verification.max_hypotheses);
  v("distinct_translation_m", l.verification.distinct_translation_m);
  v("distinct_rotation_deg", l.verification.distinct_rotation_deg);
  v("max_candidates", l.verification.max_candidates);
  v.section("refine");
  v("max_iterations", l.refine.max_iterations);
  v("max_correspondence_m", l.refine.max_correspondence_m);
  v("convergence_m", l.refine.convergence_m);
  v("point_to_plane", l.refine.point_to_plane);
  v("max_query_points", l.refine.max_query_points);
  v("max_segment_points", l.refine.max_segment_points);
  v("recent_window_m", l.refine.recent_window_m);
  v("min_recent_points", l.refine.min_recent_points);
}

// Registration to the surface layer, its covariance, the newest scans, the search of wide priors and tracking.
template <class V>
void visit_registration(V& v, PipelineConfig& c) {
  LocalizerConfig& l = c.localizer;
  v.section("registration");
  v("enabled", l.registration.enabled);
  v("window_m", l.registration.window_m);
  v("coarse_correspondence_m", l.registration.coarse_correspondence_m);
  v("coarse_leaf_m", l.registration.coarse_leaf_m);
  v("coarse_stage", l.registration.coarse_stage);
  v("max_prior_radius_m", l.registration.max_prior_radius_m);
  v("min_query_points", l.registration.min_query_points);
  v("max_last_step_m", l.registration.max_last_step_m);
  v("min_support", l.registration.min_support);
  v("min_matched_segments", l.registration.min_matched_segments);
  v("min_fitness", l.registration.min_fitness);
  v("min_axis_share", l.registration.min_axis_share);
  v.section("covariance");
  v("scale", l.covariance.scale);
  v("floor_m", l.covariance.floor_m);
  v("floor_deg", l.covariance.floor_deg);
  v.section("newest");
  v("enabled", l.newest.enabled);
  v("window_m", l.newest.window_m);
  v("leaf_m", l.newest.leaf_m);
  v("min_points", l.newest.min_points);
  v("min_fitness", l.newest.min_fitness);
  v("max_shift_m", l.newest.max_shift_m);
  v("max_turn_deg", l.newest.max_turn_deg);
  v("refuse_off_map", l.newest.refuse_off_map);
  v.section("search");
  v("enabled", l.search.enabled);
  v("max_radius_m", l.search.max_radius_m);
  v("resolution_m", l.search.resolution_m);
  v("angle_step_deg", l.search.angle_step_deg);
  v("max_query_points", l.search.max_query_points);
  v("candidates", l.search.candidates);
  v("min_separation_m", l.search.min_separation_m);
  v("min_fitness", l.search.min_fitness);
  v.section("track");
  v("enabled", l.track.enabled);
  v("leaf_m", l.track.leaf_m);
  v("window_m", l.track.window_m);
  v("min_points", l.track.min_points);
  v("max_points", l.track.max_points);
  v("min_fitness", l.track.min_fitness);
  v("ambiguity_range_m", l.track.ambiguity_range_m);
  v("max_shifted_support", l.track.max_shifted_support);
  v("min_matched_segments", l.track.min_matched_segments);
  v("min_matched_segments_near_prior", l.track.min_matched_segments_near_prior);
  v("min_support_for_fewer_matched", l.track.min_support_for_fewer_matched);
  v("fine_first_m", l.track.fine_first_m);
  v("fine_first_max_radius_m", l.track.fine_first_max_radius_m);
}

// Place recognition for cold starts, the localizer's gates, and how the map is built.
template <class V>
void visit_places_and_map(V& v, PipelineConfig& c) {
  LocalizerConfig& l = c.localizer;
  v.section("places");
  v("enabled", l.places.enabled);
  v("rings", l.places.rings);
  v("sectors", l.places.sectors);
  v("max_radius_m", l.places.max_radius_m);
  v("min_height_m", l.places.min_height_m);
  v("max_height_m", l.places.max_height_m);
  v("occlusion", l.places.occlusion);
  v("block_height_m", l.places.block_height_m);
  v("elevation_excess_deg", l.places.elevation_excess_deg);
  v("elevation_margin_deg", l.places.elevation_margin_deg);
  v("place_spacing_m", l.places.place_spacing_m);
  v("lateral_step_m", l.places.lateral_step_m);
  v("lateral_steps", l.places.lateral_steps);
  v("shortlist", l.places.shortlist);
  v("candidates", l.places.candidates);
  v("prior_radius_m", l.places.prior_radius_m);
  v("heading_tolerance_deg", l.places.heading_tolerance_deg);
  v("max_distance", l.places.max_distance);
  v("min_support", l.places.min_support);
  v("min_matched_segments", l.places.min_matched_segments);
  v("min_fitness", l.places.min_fitness);
  v("max_shifted_support", l.places.max_shifted_support);
  v("fitness_margin", l.places.fitness_margin);
  v.section("localizer");
  v("support_radius_m", l.support_radius_m);
  v("min_support", l.min_support);
  v("max_ambiguity", l.max_ambiguity);
  v("refine_pose", l.refine_pose);
  v("min_refine_fitness", l.min_refine_fitness);
  v("max_refine_rmse_voxels", l.max_refine_rmse_voxels);
  v("min_confidence", l.min_confidence);
  v("min_support_with_prior", l.min_support_with_prior);
  v("min_refine_fitness_with_prior", l.min_refine_fitness_with_prior);
  v("min_confidence_with_prior", l.min_confidence_with_prior);
  v.section("segment_map");
  v("duplicate_distance_m", c.segment_map.duplicate_distance_m);
  v.section("surfaces");
  v("enabled", c.surfaces.enabled);
  v("leaf_m", c.surfaces.leaf_m);
  v("max_range_m", c.surfaces.max_range_m);
  v("tile_m", c.surfaces.tile_m);
}

// Every field of the pipeline, section by section, in one place: the reader and the writer
// both walk these lists, so the JSON form cannot drift from the structs.
template <class V>
void visit_fields(V& v, PipelineConfig& c) {
  visit_segmentation(v, c);
  visit_matching(v, c);
  visit_registration(v, c);
  visit_places_and_map(v, c);
}

class Writer {
 public:
  void section(const char* name) { current_ = &out[name]; }
  template <class T>
  void operator()(const char* key, T& value) {
    if constexpr (std::is_enum_v<T>) {
      for (const auto& [e, n] : names(static_cast<T*>(nullptr)))
        if (e == value) (*current_)[key] = n;
    } else if constexpr (std::is_same_v<T, float>) {
      // The shortest decimal that reads back as the same float: 0.1, not 0.10000000149.
      char buf[32];
      const auto end = std::to_chars(buf, buf + sizeof buf, value).ptr;
      (*current_)[key] = std::stod(std::string(buf, end));
    } else {
      (*current_)[key] = value;
    }
  }
  json out = json::object();

 private:
  json* current_ = nullptr;
};

class Reader {
 public:
  Reader(const json& in, std::string origin) : in_(in), origin_(std::move(origin)) {}
  void section(const char* name) {
    name_ = name;
    known_sections_.insert(name);
    current_ = in_.contains(name) ? &in_.at(name) : nullptr;
    if (current_ && !current_->is_object()) fail("\"" + name_ + "\" must be an object");
  }
  template <class T>
  void operator()(const char* key, T& value) {
    known_keys_[name_].insert(key);
    if (!current_ || !current_->contains(key)) return;
    const json& j = current_->at(key);
    const std::string where = "\"" + name_ + "." + key + "\"";
    if constexpr (std::is_enum_v<T>) {
      std::string allowed;
      for (const auto& [e, n] : names(static_cast<T*>(nullptr))) {
        if (j.is_string() && j.get<std::string>() == n) return void(value = e);
        allowed += std::string(allowed.empty() ? "" : ", ") + n;
      }
      fail(where + " must be one of: " + allowed);
    } else if constexpr (std::is_same_v<T, bool>) {
      if (!j.is_boolean()) fail(where + " must be true or false");
      value = j.get<bool>();
    } else if constexpr (std::is_integral_v<T>) {
      if (!j.is_number_integer()) fail(where + " must be a whole number");
      if (std::is_unsigned_v<T> && !j.is_number_unsigned()) fail(where + " must not be negative");
      value = j.get<T>();
    } else {
      if (!j.is_number()) fail(where + " must be a number");
      value = j.get<T>();
    }
  }
  // Unknown sections or keys are typos the user wants to hear about, not silently ignore.
  void check_unknown() const {
    for (const auto& [name, value] : in_.items()) {
      if (name == "preset") continue;
      if (!known_sections_.count(name)) fail("unknown section \"" + name + "\"");
      for (const auto& [key, unused] : value.items())
        if (!known_keys_.at(name).count(key)) fail("unknown key \"" + name + "." + key + "\"");
    }
  }
  [[noreturn]] void fail(const std::string& what) const { throw IoError(origin_ + ": " + what); }

 private:
  const json& in_;
  std::string origin_;
  std::string name_;
  const json* current_ = nullptr;
  std::set<std::string> known_sections_;
  std::map<std::string, std::set<std::string>> known_keys_;
};

// The measurements behind an "auto" profile, by name, so that the JSON form cannot drift.
template <class F>
void visit_measured(InputMeasurements& m, F&& f) {
  f("scans_measured", m.scans_measured);
  f("points_per_scan", m.points_per_scan);
  f("azimuth_coverage", m.azimuth_coverage);
  f("elevation_min_deg", m.elevation_min_deg);
  f("elevation_max_deg", m.elevation_max_deg);
  f("range_p50_m", m.range_p50_m);
  f("range_p95_m", m.range_p95_m);
  f("spacing_p10_m", m.spacing_p10_m);
  f("spacing_p50_m", m.spacing_p50_m);
  f("spacing_per_range", m.spacing_per_range);
  f("scan_distance_m", m.scan_distance_m);
  f("pairs_checked", m.pairs_checked);
  f("pairs_disagreeing", m.pairs_disagreeing);
  f("ring_count", m.ring_count);
  f("ring_spacing_deg", m.ring_spacing_deg);
  f("downsampled", m.downsampled);
  f("wide_fov", m.wide_fov);
}

InputMeasurements parse_measured(const json& j, const std::string& origin) {
  if (!j.is_object()) throw IoError(origin + ": \"measured\" must be an object");
  InputMeasurements m;
  std::set<std::string> known;
  visit_measured(m, [&](const char* key, auto& value) {
    known.insert(key);
    // Maps measured before the beam layout have no rings: 0, not resolved.
    const bool since_rings = std::string(key) == "ring_count" || std::string(key) == "ring_spacing_deg";
    if (!j.contains(key) && since_rings) return;
    if (!j.contains(key)) throw IoError(origin + ": \"measured." + key + "\" is missing");
    const json& v = j.at(key);
    using T = std::decay_t<decltype(value)>;
    if constexpr (std::is_same_v<T, bool>) {
      if (!v.is_boolean()) throw IoError(origin + ": \"measured." + key + "\" must be true or false");
    } else if (!v.is_number()) {
      throw IoError(origin + ": \"measured." + key + "\" must be a number");
    }
    value = v.get<T>();
  });
  for (const auto& [key, unused] : j.items())
    if (!known.count(key)) throw IoError(origin + ": unknown key \"measured." + key + "\"");
  return m;
}

}  // namespace

void PipelineConfig::validate() const {
  local_cloud.validate();
  localizer.validate();
  segment_map.validate();
  surfaces.validate();
}

// The core's structs hold the paper's parameters; the product adds a confidence floor. On the
// demo world (seed 1) every false localization came from an unmapped street with confidence
// 0.70-0.73 and every true one had >= 0.84, so 0.8; it was then checked on a demo world it
// was not chosen on (seed 2, docs/how-defaults-were-chosen.md).
PipelineConfig::PipelineConfig() {
  localizer.min_confidence = 0.8f;
  // With a prior (tracking, GNSS) look-alikes far away cannot pass, so a low fitness floor.
  // (Chosen when the demo's tracked refusals on mapped streets showed a fitness of 0.22-0.25
  // at support 57-86: that was refinement counting a quarter of its points when it stopped in
  // its coarse phase, since fixed; the floor stays as it was.) But a wrong prior can: with
  // priors 6 m off (radius 3 m, `segmatch-eval localize --wrong-prior-m 6`) segment matching
  // answered within them at confidence 0.25-0.31 (demo 1, hku-mb 3: all false), while true
  // answers under priors had >= 0.50 on the demo, riverside02, hku-mb and hku-loop1 but one
  // (riverside02, 0.22): 0.35 (docs/how-defaults-were-chosen.md).
  localizer.min_refine_fitness_with_prior = 0.2f;
  localizer.min_confidence_with_prior = 0.35f;
}

std::vector<std::string> pipeline_preset_names() {
  return {"auto", "kitti-hdl64", "sparse-keyframes", "livox-keyframes"};
}

PipelineConfig pipeline_preset(const std::string& name) {
  PipelineConfig c;
  c.preset = name;
  if (name == "kitti-hdl64") return c;
  if (name == "auto") return c;  // unmeasured: kitti-hdl64's values (io::auto_pipeline_config measures)
  if (name == "sparse-keyframes") {
    // ../shared/data/README.md: keyframes already downsampled to ~0.2 m spacing collapse to
    // one segment with the paper's 0.1 m voxels / 2 points / 0.2 m clustering.
    SegmentationConfig& s = c.localizer.segmentation;
    s.voxel.leaf_m = 0.2f;
    s.voxel.min_points_per_voxel = 1;
    s.segmenter.cluster_distance_m = 0.4f;
    s.segmenter.min_points = 30;
    c.local_cloud.min_travel_between_scans_m = 0.0;  // keyframes are already metres apart
    // No confidence floor: the 0.8 of kitti-hdl64 was chosen on simulated HDL-64E clouds;
    // sparse keyframes give fewer segments, hence lower support, for true poses too.
    c.localizer.min_confidence = 0.0f;
    return c;
  }
  if (name == "livox-keyframes") {
    // sparse-keyframes for a small-FOV short-range sensor (Livox Avia: 70 deg, ~15 m) in a
    // small scene: few segments per local cloud, and their centroids move by up to ~1 m
    // between passes. Matching is loose (all eigen-feature neighbours within L2 3.0, 0.7 m
    // consistency, support 4) and a 30 m cylinder gives each query more segments; what keeps
    // look-alikes out is the odometry prior of loop closure (loop_detector_config below).
    // Chosen by a sweep on hku-loop1 itself (docs/how-defaults-were-chosen.md); no second Livox
    // recording was available to validate it. L2 matcher: no classifier was trained on
    // Livox segments.
    c = pipeline_preset("sparse-keyframes");
    c.preset = name;
    c.local_cloud.radius_m = 30.0;
    c.localizer.segmentation.segmenter.min_points = 20;
    c.localizer.matcher.type = MatcherType::kL2;
    c.localizer.matcher.use_shapes = false;
    c.localizer.matcher.l2_threshold = 3.0f;
    c.localizer.verification.resolution_m = 0.7f;
    c.localizer.min_support = 4;
    return c;
  }
  std::string known;
  for (const std::string& n : pipeline_preset_names()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown preset \"" + name + "\" (known: " + known + ")");
}

LoopDetectorConfig loop_detector_config(const PipelineConfig& p) {
  LoopDetectorConfig c;
  c.local_cloud = p.local_cloud;
  c.localizer = p.localizer;
  c.segment_map = p.segment_map;
  if (p.preset == "livox-keyframes") {
    c.local_cloud_every_m = 1.0;
    c.exclude_recent_distance_m = 25.0;
    c.local_cloud_history_m = 25.0;
    c.min_inliers = 4;
    c.min_confidence = 0.3f;
    c.max_drift_m = 1.0;
    c.max_drift_deg = 2.0;
  }
  if (p.preset == "auto" && p.measured && p.measured->sensor_class() == "narrow-fov") {
    // livox-keyframes' loop settings (hku-loop1; checked on hku-mb: no false loop) stated for
    // the class: objects stay in the local cloud for about 2.5 times the median range
    // (hku-loop1: 2.5 x 10.3 m ~ the 25 m found by sweep), and the drift bound grows with the
    // distance driven (1.5 %: hku-loop1's revisit after ~56 m gets ~0.85 m, where a fixed 1 m
    // held and 1.5 m let false loops through; LIO odometry drifts well under 1 %).
    const double window_m = std::max(10.0, std::round(2.5 * p.measured->range_p50_m));
    c.local_cloud_every_m = 1.0;
    c.exclude_recent_distance_m = window_m;
    c.local_cloud_history_m = window_m;
    c.min_inliers = 4;
    c.min_confidence = 0.3f;
    c.max_drift_m = 0.5;
    c.max_drift_fraction = 0.015;
    c.max_drift_deg = 2.0;
  }
  return c;
}

void take_measured_elevations(PipelineConfig& c) {
  if (!c.measured) return;
  const InputMeasurements& m = *c.measured;
  // Maps measured before elevations were: 0 .. 0, nothing known.
  if (!(m.elevation_max_deg > m.elevation_min_deg)) return;
  c.localizer.places.map_elevation_min_deg = static_cast<float>(std::max(-90.0, m.elevation_min_deg));
  c.localizer.places.map_elevation_max_deg = static_cast<float>(std::min(90.0, m.elevation_max_deg));
}

PipelineConfig parse_pipeline_config(const std::string& json_text, const std::string& origin) {
  json in;
  try {
    in = json::parse(json_text);
  } catch (const json::exception& e) {  // also out_of_range: a number too large for a double
    throw IoError(origin + ": not valid JSON: " + e.what());
  }
  if (!in.is_object()) throw IoError(origin + ": the config must be a JSON object");
  std::string preset = "kitti-hdl64";
  if (in.contains("preset")) {
    if (!in["preset"].is_string()) throw IoError(origin + ": \"preset\" must be a string");
    preset = in["preset"].get<std::string>();
  }
  PipelineConfig c;
  try {
    c = pipeline_preset(preset);
  } catch (const std::invalid_argument& e) {
    throw IoError(origin + ": " + e.what());
  }
  Reader reader(in, origin);
  visit_fields(reader, c);
  if (in.contains("measured")) {
    c.measured = parse_measured(in["measured"], origin);
    take_measured_elevations(c);
    in.erase("measured");
  }
  // How segmatch-mapbuilder --close-loops corrected the poses: a record, not a parameter.
  in.erase("loop_closure");
  reader.check_unknown();
  try {
    c.validate();
  } catch (const std::invalid_argument& e) {
    throw IoError(origin + ": invalid value: " + e.what());
  }
  return c;
}

PipelineConfig parse_map_parameters(const std::string& json_text, const std::string& origin) {
  PipelineConfig c = parse_pipeline_config(json_text, origin);
  const json in = json::parse(json_text);  // parsed once already: valid
  if (!(in.contains("refine") && in["refine"].is_object() && in["refine"].contains("max_segment_points")))
    c.localizer.refine.max_segment_points = 0;
  // Maps written before the recent window answered for the whole cloud, and held scans until
  // they left the cylinder: they still do.
  if (!(in.contains("refine") && in["refine"].is_object() && in["refine"].contains("recent_window_m")))
    c.localizer.refine.recent_window_m = 0.0f;
  if (!(in.contains("local_cloud") && in["local_cloud"].is_object() && in["local_cloud"].contains("max_scan_age_m")))
    c.local_cloud.max_scan_age_m = 0.0;
  return c;
}

PipelineConfig read_pipeline_config(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw IoError(path + ": cannot open config file");
  std::ostringstream text;
  text << f.rdbuf();
  if (f.bad()) throw IoError(path + ": read error");
  return parse_pipeline_config(text.str(), path);
}

std::string to_json(const PipelineConfig& config) {
  PipelineConfig copy = config;
  Writer writer;
  writer.out["preset"] = config.preset;
  visit_fields(writer, copy);
  if (copy.measured)
    visit_measured(*copy.measured, [&](const char* key, const auto& value) { writer.out["measured"][key] = value; });
  return writer.out.dump(2);
}

}  // namespace io
}  // namespace segmatch
