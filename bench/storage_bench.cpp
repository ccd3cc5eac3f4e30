// segmatch-bench-storage: size and speed of the SQLite segment map (issue: map database).
// Writes a synthetic city map (default 100k segments of 300-1500 points, full eigen + ESF
// descriptors) to a temporary folder, then times a full load and a segments_near() query,
// median over several runs with the file in the page cache; then opens it for serving
// (storage_serving.h) with the points read lazily and with every point in memory, and answers
// the same queries in both modes. The map carries a synthetic surface layer along its route
// (storage_surfaces.h): its MB per km, and the time to read it near a place.
#include "storage_serving.h"
#include "storage_surfaces.h"

#include <segmatch/io/pipeline_config.h>
#include <segmatch/server/map_service.h>
#include <segmatch/storage/map_reader.h>
#include <segmatch/storage/map_writer.h>

#include <fstream>
#include <iterator>
#include <optional>

#include <CLI/CLI.hpp>

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <random>
#include <vector>

using namespace segmatch;
using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

namespace {

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// User + system CPU time of the whole process: unlike wall time, barely affected by other
// programs competing for the cores.
double cpu_seconds() {
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  const auto sec = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
  return sec(usage.ru_utime) + sec(usage.ru_stime);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// An object-sized segment (0.5-8 m wide, 0.5-12 m tall) somewhere in a city of `area_m`.
Segment synthetic_segment(std::mt19937& rng, uint64_t id, float area_m, size_t points) {
  std::uniform_real_distribution<float> where(-area_m / 2, area_m / 2), unit(0.f, 1.f);
  std::uniform_real_distribution<float> width(0.5f, 8.f), height(0.5f, 12.f);
  const Eigen::Vector3f base(where(rng), where(rng), unit(rng) * 20.f);
  const Eigen::Vector3f size(width(rng), width(rng), height(rng));
  Segment s;
  s.id = id;
  s.label = static_cast<uint32_t>(rng() % 30);
  s.points.resize(points);
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  for (Point& p : s.points) {
    const Eigen::Vector3f xyz = base + size.cwiseProduct(Eigen::Vector3f(unit(rng), unit(rng), unit(rng)));
    p = {xyz.x(), xyz.y(), xyz.z(), unit(rng)};
    sum += xyz;
  }
  s.centroid = sum / float(points);
  for (float& v : s.eigen) v = unit(rng);
  for (float& v : s.esf) v = unit(rng) / 64.f;
  s.has_eigen = s.has_esf = true;
  return s;
}

// Real segments to tile a city with: a map's segments (e.g. the demo's), copied side by side,
// each copy shifted east by the map's width plus 100 m, with its trajectory length.
struct Tiles {
  Segments segments;
  std::vector<uint32_t> keyframe_of_segment;
  std::vector<storage::Keyframe> trajectory;
  uint32_t keyframes_per_copy = 1;
  float width_m = 0;
  double km = 0;  // trajectory length of one copy
};

Tiles read_tiles(const std::string& path) {
  const storage::MapReader reader = storage::MapReader::open(path);
  Tiles t;
  t.segments = reader.load_segments(&t.keyframe_of_segment);
  t.trajectory = reader.trajectory();
  for (const storage::Keyframe& k : t.trajectory) t.keyframes_per_copy = std::max(t.keyframes_per_copy, k.index + 1);
  float lo = 1e30f, hi = -1e30f;
  for (const Segment& s : t.segments) lo = std::min(lo, s.centroid.x()), hi = std::max(hi, s.centroid.x());
  t.width_m = hi - lo + 100.f;
  t.km = reader.stats().trajectory_length_m / 1000.0;
  return t;
}

Segment tile_segment(const Tiles& tiles, size_t i, uint32_t* keyframe) {
  const size_t copy = i / tiles.segments.size();
  Segment s = tiles.segments[i % tiles.segments.size()];
  const float dx = tiles.width_m * float(copy);
  s.id = i;
  s.centroid.x() += dx;
  for (Point& p : s.points) p.x += dx;
  const uint32_t k = tiles.keyframe_of_segment[i % tiles.segments.size()];
  *keyframe = k == storage::kNoKeyframe ? k : k + uint32_t(copy) * tiles.keyframes_per_copy;
  return s;
}

// The source map's trajectory once per copy, shifted with it: the route of the tiled city.
std::vector<storage::Keyframe> tiled_trajectory(const Tiles& tiles, int segments) {
  std::vector<storage::Keyframe> out;
  const size_t copies = (size_t(segments) + tiles.segments.size() - 1) / tiles.segments.size();
  for (size_t copy = 0; copy < copies; ++copy) {
    for (storage::Keyframe k : tiles.trajectory) {
      k.index += uint32_t(copy) * tiles.keyframes_per_copy;
      k.T_map_sensor.translation().x() += double(tiles.width_m) * double(copy);
      out.push_back(k);
    }
  }
  return out;
}

struct WriteResult {
  double seconds = 0;
  double commit_seconds = 0;   // COMMIT + fsync + rename, part of seconds
  double surface_seconds = 0;  // set_surfaces, part of seconds
  size_t points = 0;
  double route_km = 0;  // without the jumps between tiled copies
  std::vector<Eigen::Vector3f> centroids;
};

// The route: a straight line of a keyframe per metre for synthetic segments, else the tiles'.
std::vector<storage::Keyframe> bench_trajectory(int segments, const Tiles* tiles) {
  if (tiles) return tiled_trajectory(*tiles, segments);
  std::vector<storage::Keyframe> trajectory(size_t(segments / 50 + 1));
  for (size_t k = 0; k < trajectory.size(); ++k) {
    trajectory[k].index = uint32_t(k);
    trajectory[k].time_s = 0.1 * double(k);
    trajectory[k].T_map_sensor.translation() = Eigen::Vector3d(double(k), 0.0, 0.0);
  }
  return trajectory;
}

double route_km(const std::vector<storage::Keyframe>& trajectory) {
  double m = 0;
  for (size_t k = 1; k < trajectory.size(); ++k) {
    const double step =
        (trajectory[k].T_map_sensor.translation() - trajectory[k - 1].T_map_sensor.translation()).norm();
    if (step <= 50.0) m += step;
  }
  return m / 1000.0;
}

WriteResult write_map(const std::string& path, int segments, float area_m, const Tiles* tiles, float surface_tile_m) {
  storage::MapMetadata metadata;
  metadata.name = "storage bench";
  metadata.tool_version = "segmatch-bench-storage";
  metadata.parameters_json = io::to_json(io::pipeline_preset("kitti-hdl64"));
  std::mt19937 rng(42);
  std::uniform_int_distribution<size_t> point_count(300, 1500);
  WriteResult result;
  storage::MapWriter writer = storage::MapWriter::create(path, metadata, true);
  for (int first = 0; first < segments; first += 1000) {
    Segments batch;
    std::vector<uint32_t> keyframes;
    for (int i = first; i < std::min(segments, first + 1000); ++i) {
      uint32_t keyframe = uint32_t(i / 50);
      batch.push_back(tiles ? tile_segment(*tiles, size_t(i), &keyframe)
                            : synthetic_segment(rng, uint64_t(i), area_m, point_count(rng)));
      keyframes.push_back(keyframe);
      result.points += batch.back().points.size();
      result.centroids.push_back(batch.back().centroid);
    }
    const auto t = Clock::now();  // time the storage, not the synthetic data
    writer.add_segments(batch, keyframes);
    result.seconds += seconds_since(t);
  }
  const std::vector<storage::Keyframe> trajectory = bench_trajectory(segments, tiles);
  result.route_km = route_km(trajectory);
  if (surface_tile_m > 0.f) {
    const PointCloud surfaces = bench::synthetic_surfaces(trajectory, 0.25f);
    const auto s = Clock::now();
    writer.set_surfaces(surfaces, 0.25f, surface_tile_m);
    result.surface_seconds = seconds_since(s);
    result.seconds += result.surface_seconds;
  }
  const auto t = Clock::now();
  writer.set_trajectory(trajectory);
  std::ifstream model(SEGMATCH_SOURCE_DIR "/maps/models/default-rf.yml", std::ios::binary);
  writer.set_classifier({storage::kClassifierFormatRTreesYaml, std::string(std::istreambuf_iterator<char>(model), {})});
  const auto c = Clock::now();
  writer.commit();
  result.commit_seconds = seconds_since(c);
  result.seconds += seconds_since(t);
  return result;
}

void print(const char* set, const bench::QueryFigures& q) {
  std::printf("; %d %s queries: median %.1f ms, p90 %.1f ms, %d localized (%d within 5 cm)", q.queries, set,
              q.median_ms, q.p90_ms, q.localized, q.correct);
  if (q.point_reads + q.cache_hits)
    std::printf(", %llu segments' points read, %llu from the cache", q.point_reads, q.cache_hits);
}

void print(const char* mode, const char* cache, const bench::ServingFigures& f) {
  if (!f.ok) {
    std::printf("open for serving, points %-6s, %s cache: FAILED\n", mode, cache);
    return;
  }
  std::printf("open for serving, points %-6s, %s cache: %.3f s, resident +%.0f MB heap, +%.0f MB file pages", mode,
              cache, f.open_s, f.heap_mb, f.file_mb);
  print("route", f.route);
  print("random-place", f.random);
  std::printf("; after them +%.0f MB heap, +%.0f MB file pages\n", f.heap_after_mb, f.file_after_mb);
}

// Three fresh processes per mode (warm page cache), lazy and in memory in turn, then the same
// with a cold page cache if asked; the medians, and the time lazy reads add to a query.
void report_serving(const std::string& path, bool drop_caches) {
  for (const bool cold : {false, true}) {
    if (cold && !drop_caches) break;
    const char* cache = cold ? "cold" : "warm";
    std::vector<double> lazy_open, memory_open, lazy_route, memory_route, lazy_random, memory_random;
    bool same_answers = true;
    for (int run = 0; run < 3; ++run) {
      const bench::ServingFigures lazy = bench::open_for_serving(path, server::MapPoints::kLazy, cold);
      print("lazy", cache, lazy);
      const bench::ServingFigures memory = bench::open_for_serving(path, server::MapPoints::kMemory, cold);
      print("memory", cache, memory);
      if (!lazy.ok || !memory.ok) continue;
      same_answers = same_answers && lazy.route.pose_sum == memory.route.pose_sum &&
                     lazy.random.pose_sum == memory.random.pose_sum && lazy.route.localized == memory.route.localized &&
                     lazy.random.localized == memory.random.localized;
      lazy_open.push_back(lazy.open_s), memory_open.push_back(memory.open_s);
      lazy_route.push_back(lazy.route.median_ms), memory_route.push_back(memory.route.median_ms);
      lazy_random.push_back(lazy.random.median_ms), memory_random.push_back(memory.random.median_ms);
    }
    if (lazy_open.empty()) continue;
    std::printf(
        "open for serving, %s cache, median of %zu: lazy %.3f s, memory %.3f s; lazy point reads add %+.1f ms "
        "a route query (%.1f vs %.1f ms), %+.1f ms a random-place query (%.1f vs %.1f ms); answers %s\n",
        cache, lazy_open.size(), median(lazy_open), median(memory_open), median(lazy_route) - median(memory_route),
        median(lazy_route), median(memory_route), median(lazy_random) - median(memory_random), median(lazy_random),
        median(memory_random), same_answers ? "identical" : "DIFFER");
  }
}

// Opens, fully loads and queries the written map `runs` times; prints the medians. False if a
// load does not give back every segment.
bool time_reads(const std::string& path, const WriteResult& written, int segments, int runs, float radius_m) {
  std::vector<double> open_s, load_s, load_cpu_s, near_s;
  std::vector<size_t> near_counts;
  std::mt19937 rng(7);
  for (int run = 0; run < runs; ++run) {
    auto t = Clock::now();
    const storage::MapReader reader = storage::MapReader::open(path);
    open_s.push_back(seconds_since(t));
    t = Clock::now();
    const double cpu = cpu_seconds();
    const Segments all = reader.load_segments();
    load_s.push_back(seconds_since(t));
    load_cpu_s.push_back(cpu_seconds() - cpu);
    if (all.size() != size_t(segments)) return false;
    const Eigen::Vector3f center = written.centroids[rng() % written.centroids.size()];
    t = Clock::now();
    near_counts.push_back(reader.segments_near(center, radius_m).size());
    near_s.push_back(seconds_since(t));
  }
  std::printf("open: median %.2f ms\n", median(open_s) * 1e3);
  std::printf("full load_segments(): median %.3f s over %d runs (min %.3f, max %.3f) [page cache warm]\n",
              median(load_s), runs, *std::min_element(load_s.begin(), load_s.end()),
              *std::max_element(load_s.begin(), load_s.end()));
  std::printf("full load CPU time (all threads): median %.3f s\n", median(load_cpu_s));
  std::printf("segments_near(r = %.0f m): median %.2f ms, %zu segments on median\n", radius_m, median(near_s) * 1e3,
              size_t(median(std::vector<double>(near_counts.begin(), near_counts.end()))));
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Benchmark the SQLite segment map: size, write, load and spatial query"};
  int segments = 100000, runs = 5;
  float area_m = 3000.f, radius_m = 50.f;
  std::string folder = (fs::temp_directory_path() / ("segmatch_bench_storage_" + std::to_string(::getpid()))).string();
  app.add_option("--segments", segments, "segments in the map")->check(CLI::Range(1, 10000000));
  app.add_option("--runs", runs, "timed runs (median reported)")->check(CLI::Range(1, 100));
  app.add_option("--area", area_m, "side of the square city in metres");
  app.add_option("--radius", radius_m, "segments_near() and surface near() radius in metres");
  float surface_tile_m = 32.f;
  app.add_option("--surface-tile", surface_tile_m,
                 "tile size of the synthetic surface layer (ground and facades along the route, 0.25 m); 0: none");
  app.add_option("--dir", folder, "scratch folder (removed afterwards unless --keep)");
  bool keep = false;
  std::string from;
  app.add_option("--from", from,
                 "tile the city with this map's real segments (e.g. the demo's) instead of "
                 "synthetic ones (random points and descriptors: incompressible, the worst case)");
  app.add_flag("--keep", keep, "keep the map (DIR/bench.segmap)");
  std::string existing;
  app.add_option("--map", existing, "measure this map instead of writing one (no write, no segments_near timing)")
      ->check(CLI::ExistingFile);
  bool drop_caches = false;
  app.add_flag("--drop-caches", drop_caches,
               "also open for serving with a cold page cache (needs root: writes /proc/sys/vm/drop_caches, which "
               "empties the whole machine's cache)");
  CLI11_PARSE(app, argc, argv);
  std::string why;
  if (drop_caches && !bench::can_drop_caches(&why)) {
    std::fprintf(stderr, "--drop-caches: %s\n", why.c_str());
    return 2;
  }
  if (!existing.empty()) {
    std::printf("map: %s, %.1f MB\n", existing.c_str(), double(fs::file_size(existing)) / 1e6);
    report_serving(existing, drop_caches);
    return 0;
  }

  fs::create_directories(folder);
  const std::string path = (fs::path(folder) / "bench.segmap").string();
  std::optional<Tiles> tiles;
  if (!from.empty()) tiles = read_tiles(from);
  const WriteResult written = write_map(path, segments, area_m, tiles ? &*tiles : nullptr, surface_tile_m);
  const double size_mb = double(fs::file_size(path)) / 1e6;
  std::printf("map: %d segments, %zu points (%.0f per segment), %.0f x %.0f m\n", segments, written.points,
              double(written.points) / segments, area_m, area_m);
  std::printf("file size: %.1f MB (%.1f MB per 100k segments, %.2f bytes per point all-in)\n", size_mb,
              size_mb * 1e5 / segments, size_mb * 1e6 / double(written.points));
  if (tiles) {
    const double km = tiles->km * double(segments) / double(tiles->segments.size());
    std::printf("tiled from %s: %zu segments and %.3f km a copy: %.1f MB per km\n", from.c_str(),
                tiles->segments.size(), tiles->km, size_mb / km);
  }
  std::printf(
      "write (add_segments + surfaces + trajectory + classifier + commit): %.2f s, of which set_surfaces "
      "%.2f s, commit (COMMIT + fsync + rename) %.2f s\n",
      written.seconds, written.surface_seconds, written.commit_seconds);

  if (!time_reads(path, written, segments, runs, radius_m)) return 1;
  if (surface_tile_m > 0.f) bench::report_surfaces(path, written.route_km, runs, radius_m);
  report_serving(path, drop_caches);
  std::error_code ec;
  if (!keep) fs::remove_all(folder, ec);
  return 0;
}
