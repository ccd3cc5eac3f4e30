// segmatch-mapinfo: what is in a segment map (metadata, stats, extent), an integrity check,
// exports for viewing (coloured PLY / PCD of the segments, a top-down PNG), and the upgrade of
// an older map file to this build's schema.
#include "map_export.h"

#include <segmatch/io/auto_profile.h>
#include <segmatch/io/error.h>
#include <segmatch/storage/map_reader.h>
#include <segmatch/storage/map_writer.h>

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <optional>

namespace fs = std::filesystem;
using namespace segmatch;

namespace {

void print_metadata(const storage::MapReader& map) {
  const storage::MapMetadata& m = map.metadata();
  std::printf("map:            %s\n", map.path().c_str());
  std::printf("name:           %s\n", m.name.c_str());
  std::printf("frame:          %s\n", m.frame.c_str());
  std::printf("created:        %s\n", m.created_utc.c_str());
  std::printf("tool version:   %s\n", m.tool_version.c_str());
  if (map.schema_version() < storage::kSchemaVersion)
    std::printf(
        "schema version: %d (older than this build's %d: readable; `segmatch-mapinfo --upgrade OLD NEW` "
        "rewrites it, smaller)\n",
        map.schema_version(), storage::kSchemaVersion);
  else
    std::printf("schema version: %d\n", map.schema_version());
}

// The surface layer in one line (schema 4; older maps and maps upgraded from them have none).
void print_surfaces(const storage::MapReader& map) {
  const std::optional<storage::SurfaceLayer> layer = map.surfaces();
  if (layer) {
    std::printf("surfaces:       leaf %.2f m, tile %.1f m, %llu tiles, %llu points, %.2f MB\n", layer->leaf_m,
                layer->tile_m, static_cast<unsigned long long>(layer->tile_count),
                static_cast<unsigned long long>(layer->point_count), static_cast<double>(layer->stored_bytes) / 1e6);
  } else if (map.schema_version() < 4) {
    std::printf("surfaces:       no surface layer (map written before schema 4; rebuild it to get one)\n");
  } else {
    std::printf(
        "surfaces:       no surface layer (built without one, or upgraded from a map written before schema 4; "
        "rebuild the map from its traversal to get one)\n");
  }
}

int upgrade(const std::string& old_path, const std::string& new_path, bool overwrite) {
  const int from = storage::upgrade_map(old_path, new_path, overwrite);
  std::printf("upgraded %s (schema %d, %.2f MB) -> %s (schema %d, %.2f MB)\n", old_path.c_str(), from,
              static_cast<double>(fs::file_size(old_path)) / 1e6, new_path.c_str(), storage::kSchemaVersion,
              static_cast<double>(fs::file_size(new_path)) / 1e6);
  if (!storage::MapReader::open(new_path).surfaces()) {
    std::printf(
        "the new map has no surface layer (the old map holds no scans to make one from): rebuild the map "
        "from its traversal (segmatch-mapbuilder) to get one\n");
  }
  return 0;
}

void print_stats(const storage::MapReader& map, const Segments& segments) {
  const storage::MapStats s = map.stats();
  std::printf("segments:       %zu\n", s.segments);
  std::printf("points:         %zu\n", s.points);
  std::printf("keyframes:      %zu\n", s.keyframes);
  std::printf("trajectory:     %.3f km\n", s.trajectory_length_m / 1000.0);
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
  for (const Segment& seg : segments)
    for (const Point& p : seg.points) lo = lo.cwiseMin(p.xyz()), hi = hi.cwiseMax(p.xyz());
  if (lo.x() <= hi.x())
    std::printf("extent:         x %.1f..%.1f  y %.1f..%.1f  z %.1f..%.1f m\n", lo.x(), hi.x(), lo.y(), hi.y(), lo.z(),
                hi.z());
  else
    std::printf("extent:         (no points)\n");
  const auto classifier = map.classifier();
  std::printf(
      "classifier:     %s\n",
      classifier ? (classifier->format + ", " + std::to_string(classifier->bytes.size()) + " bytes").c_str() : "none");
  print_surfaces(map);
  std::printf("file size:      %.2f MB\n", static_cast<double>(fs::file_size(map.path())) / 1e6);
}

int check(const storage::MapReader& map) {
  const std::vector<std::string> problems = map.check_integrity();
  if (problems.empty()) {
    std::printf("integrity:      ok\n");
    return 0;
  }
  std::printf("integrity:      %zu problem(s)\n", problems.size());
  for (const std::string& p : problems) std::printf("  - %s\n", p.c_str());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Show what a SegMatch segment map holds; check it; export it for viewing"};
  std::string path, ply, pcd, png;
  std::vector<std::string> upgrade_paths;
  bool run_check = false, overwrite = false;
  auto* map_opt = app.add_option("map", path, "map file (.sqlite)");
  auto* upgrade_opt = app.add_option("--upgrade", upgrade_paths,
                                     "OLD NEW: rewrite map OLD in this build's schema as NEW (lossless; OLD is kept)")
                          ->expected(2)
                          ->excludes(map_opt);
  app.add_flag("--overwrite", overwrite, "with --upgrade: replace NEW if it exists")->needs(upgrade_opt);
  app.add_flag("--check", run_check, "full integrity check (exit 1 listing the problems)");
  auto* ply_opt = app.add_option("--export-ply", ply, "write all segments' points, coloured per segment (ASCII PLY)");
  app.add_option("--export-pcd", pcd, "same as ASCII PCD with an rgb field")->excludes(ply_opt);
  app.add_option("--png", png, "top-down picture: segments, trajectory, scale bar");
  cli::add_version_flag(app, "segmatch-mapinfo");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (upgrade_paths.empty() && path.empty()) {
    std::fprintf(stderr, "segmatch-mapinfo: error: give a map file, or --upgrade OLD NEW\n");
    return 2;
  }
  try {
    if (!upgrade_paths.empty()) return upgrade(upgrade_paths[0], upgrade_paths[1], overwrite);
    const storage::MapReader map = storage::MapReader::open(path);
    print_metadata(map);
    // Before anything else reads the file: a damaged map is reported, not half-printed.
    if (run_check && check(map) != 0) return 1;
    const Segments segments = map.load_segments();
    print_stats(map, segments);
    std::printf("parameters:\n%s\n", map.metadata().parameters_json.c_str());
    // The profile in words (what the input measured like, what was chosen), when it parses.
    try {
      std::printf("profile:\n%s\n",
                  io::describe_profile(io::parse_pipeline_config(map.metadata().parameters_json, path)).c_str());
    } catch (const io::IoError& e) {
      std::printf("profile: the stored parameters do not parse (%s)\n", e.what());
    }
    if (!ply.empty()) mapbuilder::write_colored_ply(ply, segments), std::printf("wrote %s\n", ply.c_str());
    if (!pcd.empty()) mapbuilder::write_colored_pcd(pcd, segments), std::printf("wrote %s\n", pcd.c_str());
    if (!png.empty()) {
      mapbuilder::draw_top_down_png(png, segments, map.trajectory());
      std::printf("wrote %s\n", png.c_str());
    }
    return 0;
  } catch (const std::exception& e) {  // io::IoError, storage::StorageError and the rest
    std::fprintf(stderr, "segmatch-mapinfo: error: %s\n", e.what());
    return 1;
  }
}
