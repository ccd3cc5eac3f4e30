#include "build_map.h"

#include <segmatch/cli/tool.h>
#include "loop_poses.h"

#include <segmatch/cli/progress.h>
#include <segmatch/core/mapping/map_builder.h>
#include <segmatch/core/matching/matcher.h>
#include <segmatch/io/auto_profile.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/sequence.h>
#include <segmatch/storage/map_writer.h>

#include <algorithm>
#include <cmath>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace fs = std::filesystem;

namespace segmatch::mapbuilder {
namespace {

// Refuses before any work is done, so an existing map is never put at risk by a typo.
void check_output(const BuildOptions& o) {
  const fs::path out(o.output);
  if (fs::is_directory(out)) throw UsageError("output " + o.output + " is a folder, not a map file");
  if (fs::exists(out) && !o.force)
    throw UsageError("output " + o.output + " already exists: pass --force to replace it");
  const fs::path folder = out.has_parent_path() ? out.parent_path() : fs::path(".");
  if (!fs::is_directory(folder)) throw UsageError("output folder " + folder.string() + " does not exist");
}

// A config file or a named preset as given; otherwise (or with --preset auto) the scans to be
// used are measured and the parameters derived from them (io/auto_profile.h).
io::PipelineConfig load_config(const BuildOptions& o, const io::Sequence& seq, size_t first, size_t last,
                               size_t stride) {
  if (!o.config_path.empty()) return io::read_pipeline_config(o.config_path);
  if (!o.preset.empty() && o.preset != "auto") {
    try {
      return io::pipeline_preset(o.preset);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--preset: ") + e.what());
    }
  }
  io::PipelineConfig c = io::auto_pipeline_config(io::measure_sequence(seq, first, last, stride));
  std::fprintf(o.print_config ? stderr : stdout, "%s\n", io::describe_profile(c).c_str());
  return c;
}

MapBuilderConfig builder_config(const io::PipelineConfig& pipeline, double map_every_m) {
  MapBuilderConfig c;
  c.local_cloud = pipeline.local_cloud;
  c.segmentation = pipeline.localizer.segmentation;
  c.segment_map = pipeline.segment_map;
  c.surfaces = pipeline.surfaces;
  c.map_every_m = map_every_m;
  try {
    c.validate();
  } catch (const std::invalid_argument& e) {
    throw UsageError(std::string("invalid configuration: ") + e.what());
  }
  return c;
}

// The explicit model must be valid; the default one is optional (a fresh checkout has none).
std::optional<storage::ClassifierBlob> load_classifier(const BuildOptions& o) {
  if (o.no_classifier) return std::nullopt;
  std::string path = o.classifier_path;
  if (path.empty()) {
    path = cli::shipped_model("default-rf.yml");
    if (path.empty()) {
      std::fprintf(stderr,
                   "segmatch-mapbuilder: warning: the default classifier (share/segmatch/models/default-rf.yml) "
                   "is not installed, building the map without a classifier (pass --classifier FILE to add one)\n");
      return std::nullopt;
    }
  }
  storage::ClassifierBlob blob{storage::kClassifierFormatRTreesYaml,
                               io::read_file_bytes(path, "classifier model file")};
  try {
    RandomForestMatcher::load(blob.bytes);
  } catch (const std::exception& e) {
    throw io::IoError(path + ": not a valid classifier model: " + e.what());
  }
  return blob;
}

struct ScanRange {
  size_t first = 0, last = 0, stride = 1;
  size_t count() const { return (last - first) / stride + 1; }
};

ScanRange scan_range(const BuildOptions& o, const io::Sequence& seq) {
  const size_t size = seq.size();
  ScanRange r{o.first.value_or(0), o.last.value_or(size - 1), o.stride};
  const std::string where = " (" + seq.folder() + " has scans 0.." + std::to_string(size - 1) + ")";
  if (r.stride == 0) throw UsageError("--stride must be at least 1");
  if (r.first >= size) throw UsageError("--first " + std::to_string(r.first) + " is past the last scan" + where);
  if (r.last >= size) throw UsageError("--last " + std::to_string(r.last) + " is past the last scan" + where);
  if (r.first > r.last)
    throw UsageError("empty scan range: --first " + std::to_string(r.first) + " is after --last " +
                     std::to_string(r.last) + ", 0 scans to map");
  return r;
}

// The parameters used; with --close-loops also what the loop closure did to the poses.
storage::MapMetadata metadata_for(const BuildOptions& o, const io::PipelineConfig& config,
                                  const std::optional<LoopCorrectedPoses>& corrected) {
  storage::MapMetadata m;
  m.name = o.name.empty() ? fs::path(o.output).stem().string() : o.name;
  m.tool_version = std::string("segmatch-mapbuilder ") + SEGMATCH_VERSION;
  m.parameters_json = io::to_json(config);
  if (corrected) {
    nlohmann::json j = nlohmann::json::parse(m.parameters_json);
    j["loop_closure"] = corrected->summary;
    j["loop_closure"]["odometry"] = o.odometry_path.empty() ? "poses.txt" : o.odometry_path;
    m.parameters_json = j.dump(2);
  }
  return m;
}

std::vector<size_t> frames_of(const ScanRange& r) {
  std::vector<size_t> frames;
  for (size_t i = r.first; i <= r.last; i += r.stride) frames.push_back(i);
  return frames;
}

void print_summary(const MapBuilder& b, size_t scans, double seconds, const std::string& path) {
  const double km = b.distance_driven_m() / 1000.0;
  const double bytes = static_cast<double>(fs::file_size(path));
  std::printf("map:          %s\n", path.c_str());
  std::printf("driven:       %.3f km\n", km);
  std::printf("scans:        %zu\n", scans);
  std::printf("local clouds: %zu\n", b.local_clouds());
  std::printf("segments:     %zu (from %zu extracted views)\n", b.segments().size(), b.extracted_segments());
  std::printf("build time:   %s (%.1f scans/s)\n", cli::Progress::format_duration(seconds).c_str(),
              seconds > 0 ? scans / seconds : 0.0);
  char per_km[64] = "";
  if (km > 0) std::snprintf(per_km, sizeof per_km, " (%.2f MB/km)", bytes / 1e6 / km);
  std::printf("file size:    %.2f MB%s\n", bytes / 1e6, per_km);
}

// Points are 32-bit floats: 1e5 m from the origin a float moves in steps of 8 mm, 1e6 m in 6 cm,
// 1e7 m in 1 m, where no 0.1 m segment survives (ExtremeInput.CityTenThousandKilometresFromTheOrigin).
// Poses in UTM or ECEF need a local origin; say so before building a map that cannot work.
void warn_far_from_origin(const io::Sequence& seq, const std::vector<size_t>& frames) {
  double farthest = 0.0;
  for (size_t i : frames) farthest = std::max(farthest, seq.poses()[i].translation().cwiseAbs().maxCoeff());
  if (farthest <= 1e5) return;
  const float at = static_cast<float>(farthest);
  const double step = double(std::nextafter(at, 2.f * at) - at);
  std::fprintf(stderr,
               "segmatch-mapbuilder: warning: the poses reach %.0f km from the origin, where points (32-bit floats) "
               "move in steps of %.3f m; subtract a local origin from the poses (e.g. the first pose) to keep "
               "centimetres\n",
               farthest / 1e3, step);
}

// An empty or nearly empty map localizes nothing, and a user finds out only when the fleet
// queries it: refuse it here, naming what the profile measured and what it chose. The floor
// (50 per km) is 30-70 times below every map the project builds from real or simulated drives
// (docs/measurements.md).
void check_segment_count(const MapBuilder& b, const io::PipelineConfig& config, double min_per_km) {
  const size_t segments = b.segments().size();
  const double km = b.distance_driven_m() / 1000.0;
  const double floor = std::max(1.0, std::floor(min_per_km * km));
  if (static_cast<double>(segments) >= floor) return;
  const std::string sensor = config.measured ? "sensor class " + config.measured->sensor_class()
                                             : "preset " + config.preset + " (the input not measured)";
  const std::string chose = io::describe_choice(config);
  char what[256];
  std::snprintf(
      what, sizeof what,
      "the segmentation kept %zu segments (from %zu extracted views) over %.3f km driven, at least %.0f expected",
      segments, b.extracted_segments(), km, floor);
  throw TooFewSegments(std::string(what) + "; no map written. " + sensor + ", " + chose +
                       ". Sparse scans need smaller clusters or fewer points per voxel: try another --preset, or "
                       "--print-config, edit voxel and segmenter, and pass the file with --config" +
                       (segments > 0 ? " (--min-segments-per-km 0 writes this sparse map anyway)" : ""));
}

}  // namespace

int build_map(const BuildOptions& o, const volatile std::sig_atomic_t* stop_signal) {
  const auto start = std::chrono::steady_clock::now();
  if (!o.print_config) check_output(o);
  if (!fs::exists(o.input)) throw UsageError("input " + o.input + " does not exist");
  if (!o.odometry_path.empty() && !fs::is_regular_file(o.odometry_path))
    throw UsageError("--odometry " + o.odometry_path + " is not a file");
  io::SequenceOptions so;
  so.poses_path = o.odometry_path;
  so.bag = o.bag;
  const io::Sequence seq = io::Sequence::open(o.input, so);
  if (!seq.source_note().empty()) std::fprintf(stderr, "%s\n", seq.source_note().c_str());
  const ScanRange range = scan_range(o, seq);
  // Read before the recording is measured (seconds): a wrong model file fails at once.
  const std::optional<storage::ClassifierBlob> classifier = o.print_config ? std::nullopt : load_classifier(o);
  const io::PipelineConfig config = load_config(o, seq, range.first, range.last, range.stride);
  MapBuilder builder(builder_config(config, o.map_every_m));
  if (o.print_config) {
    std::printf("%s\n", io::to_json(config).c_str());
    return 0;
  }
  const std::vector<size_t> frames = frames_of(range);
  warn_far_from_origin(seq, frames);
  std::optional<LoopCorrectedPoses> corrected;
  if (o.close_loops) corrected = close_loops_first(seq, frames, config, classifier, o.scan_edges, stop_signal);

  // Created before the loop: an unwritable target fails now, and an interrupted build leaves
  // nothing behind (the writer's destructor deletes its temporary file).
  storage::MapWriter writer = storage::MapWriter::create(o.output, metadata_for(o, config, corrected), o.force);
  std::vector<storage::Keyframe> trajectory;
  trajectory.reserve(range.count());
  {
    cli::Progress progress("map " + fs::path(o.input).filename().string(), range.count(), "scans");
    for (size_t k = 0; k < frames.size(); ++k) {
      if (*stop_signal) break;
      const size_t i = frames[k];
      const io::CloudData scan = seq.scan(i);
      const Pose3d& T_map_sensor = corrected ? corrected->T_map_sensor[k] : seq.poses()[i];
      builder.add_scan(scan.points, T_map_sensor, static_cast<uint32_t>(i),
                       scan.labels.empty() ? nullptr : &scan.labels);
      trajectory.push_back({static_cast<uint32_t>(i), seq.times()[i], T_map_sensor});
      progress.advance();
    }
    if (!*stop_signal) builder.finish();
  }
  auto interrupted = [&] {
    if (!*stop_signal) return false;
    std::fprintf(stderr, "segmatch-mapbuilder: interrupted, no map written%s\n",
                 fs::exists(o.output) ? " (the existing map is unchanged)" : "");
    return true;
  };
  if (interrupted()) return 128 + *stop_signal;
  check_segment_count(builder, config, o.min_segments_per_km);
  writer.add_segments(builder.segments(), builder.keyframe_of_segment());
  writer.set_trajectory(trajectory);
  if (classifier) writer.set_classifier(*classifier);
  const PointCloud surfaces = config.surfaces.enabled ? builder.surface_points() : PointCloud{};
  if (config.surfaces.enabled) writer.set_surfaces(surfaces, config.surfaces.leaf_m, config.surfaces.tile_m);
  if (interrupted()) return 128 + *stop_signal;  // last chance: after commit() the map exists
  writer.commit();
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  print_summary(builder, trajectory.size(), seconds, o.output);
  if (config.surfaces.enabled)
    std::printf("surfaces:     %zu points (leaf %.2f m)\n", surfaces.size(), config.surfaces.leaf_m);
  return 0;
}

}  // namespace segmatch::mapbuilder
