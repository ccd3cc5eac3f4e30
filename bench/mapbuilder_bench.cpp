// Map building throughput on simulated HDL-64E scans: the scans are simulated first, so only
// the mapping (accumulation, crop, segmentation, description, merging) and the map write are
// timed, on one core.
#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/mapping/map_builder.h"
#include "segmatch/core/preprocess/voxel_accumulator.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/raycaster.h"
#include "segmatch/storage/map_writer.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>

#include <sys/resource.h>
#include <time.h>

using namespace segmatch;
using Clock = std::chrono::steady_clock;

namespace {

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// CPU time of the calling thread: the mapping's own cost, whatever else loads the machine.
double thread_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Scans the local cloud keeps (>= 1 m apart) of the first route_m of the traversal; the
// others it drops at once (one distance test), so they cost nothing worth timing.
std::vector<size_t> kept_frames(const sim::Traversal& t, double route_m, double step_m) {
  std::vector<size_t> frames;
  for (size_t i = 0; i < t.size() && t.odometer_m[i] <= route_m; ++i)
    if (frames.empty() ||
        (t.T_world_lidar[i].translation() - t.T_world_lidar[frames.back()].translation()).norm() >= step_m)
      frames.push_back(i);
  return frames;
}

// The same scans through the reference (LocalCloud + voxel_filter) and the accumulator, with
// labels, cropped at the scans where the builder segmented. Exit code 0 if they agree.
int compare_voxels(const MapBuilderConfig& config, const sim::Traversal& t, const std::vector<size_t>& frames,
                   const std::vector<sim::SimulatedScan>& scans) {
  LocalCloud reference(config.local_cloud);
  VoxelAccumulator accumulator(config.local_cloud, config.segmentation.voxel);
  size_t clouds = 0, voxels = 0, size_mismatches = 0, label_mismatches = 0;
  double max_diff_m = 0.0, odometer = 0.0, segmented_at = 0.0;
  for (size_t k = 0; k < frames.size(); ++k) {
    const Pose3d& T = t.T_world_lidar[frames[k]];
    if (k > 0) odometer += (T.translation() - t.T_world_lidar[frames[k - 1]].translation()).norm();
    reference.add_scan(scans[k].points, T, &scans[k].labels);
    accumulator.add_scan(scans[k].points, T, &scans[k].labels);
    if (odometer - segmented_at < config.map_every_m && k + 1 < frames.size()) continue;
    segmented_at = odometer;
    std::vector<uint32_t> cropped_labels, expected_labels, got_labels;
    const PointCloud cropped = reference.crop(T, &cropped_labels);
    const PointCloud expected = voxel_filter(cropped, config.segmentation.voxel, &cropped_labels, &expected_labels);
    const PointCloud got = accumulator.crop(T, &got_labels);
    ++clouds;
    voxels += expected.size();
    if (got.size() != expected.size()) {
      ++size_mismatches;
      continue;
    }
    for (size_t i = 0; i < got.size(); ++i) {
      max_diff_m = std::max({max_diff_m, double(std::abs(got[i].x - expected[i].x)),
                             double(std::abs(got[i].y - expected[i].y)), double(std::abs(got[i].z - expected[i].z))});
      label_mismatches += got_labels[i] != expected_labels[i];
    }
  }
  std::printf(
      "voxel check:      %zu local clouds, %zu voxels: %zu with another voxel count, max |diff| %.2g m, "
      "%zu labels differ\n",
      clouds, voxels, size_mismatches, max_diff_m, label_mismatches);
  return size_mismatches == 0 && label_mismatches == 0 && max_diff_m < 1e-4 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Map building throughput (segmatch-mapbuilder's core) on simulated HDL-64E scans"};
  std::string preset = "tiny";
  uint64_t seed = 3;
  double route_m = 150.0;
  int threads = 0;
  double subsample_leaf_m = 0.0;
  app.add_option("--preset", preset, "simulated world: tiny or demo")->check(CLI::IsMember({"tiny", "demo"}));
  app.add_option("--seed", seed, "world seed");
  app.add_option("--route-m", route_m, "metres of the mapping traversal to map (scans are held in memory)");
  app.add_option("--threads", threads, "threads simulating the scans beforehand (0: one per core)");
  app.add_option("--subsample-leaf-m", subsample_leaf_m, "LocalCloudConfig.subsample_leaf_m (default 0: off)");
  bool check_voxels = false;
  app.add_flag("--check-voxels", check_voxels,
               "afterwards, compare VoxelAccumulator::crop with voxel_filter(LocalCloud::crop) at every local cloud");
  CLI11_PARSE(app, argc, argv);
  if (threads <= 0) threads = std::max(1u, std::thread::hardware_concurrency());

  const sim::DatasetConfig c = sim::dataset_preset(preset, seed);
  const sim::World world = sim::generate_world(c.world);
  Rng rng(mix_seed(seed, 0x7a5e));
  const sim::Traversal t =
      sim::drive(world, sim::plan_route(world.streets, std::max(route_m, c.first_length_m), rng), c.drive_first);
  MapBuilderConfig config;
  config.local_cloud.subsample_leaf_m = subsample_leaf_m;
  const std::vector<size_t> frames = kept_frames(t, route_m, config.local_cloud.min_travel_between_scans_m);
  std::fprintf(stderr, "simulating %zu scans (%s world, seed %llu)...\n", frames.size(), preset.c_str(),
               static_cast<unsigned long long>(seed));
  const sim::RayCaster caster(world.scene());
  const auto scans = sim::simulate_scans(caster, sim::hdl64e(), t.T_world_lidar, frames, threads);

  MapBuilder builder(config);
  std::vector<double> cloud_ms;
  const double cpu_start = thread_cpu_s();
  const auto start = Clock::now();
  for (size_t k = 0; k < frames.size(); ++k) {
    const auto t0 = Clock::now();
    if (builder.add_scan(scans[k].points, t.T_world_lidar[frames[k]], static_cast<uint32_t>(frames[k])))
      cloud_ms.push_back(seconds_since(t0) * 1e3);
  }
  builder.finish();
  const double build_s = seconds_since(start), build_cpu_s = thread_cpu_s() - cpu_start;

  const std::string path = (std::filesystem::temp_directory_path() / "segmatch_mapbuilder_bench.sqlite").string();
  const auto write_start = Clock::now();
  storage::MapWriter writer = storage::MapWriter::create(path, storage::MapMetadata{}, true);
  writer.add_segments(builder.segments(), builder.keyframe_of_segment());
  std::vector<storage::Keyframe> trajectory;
  for (size_t f : frames) trajectory.push_back({static_cast<uint32_t>(f), t.times_s[f], t.T_world_lidar[f]});
  writer.set_trajectory(trajectory);
  writer.commit();
  const double write_s = seconds_since(write_start);
  const double km = builder.distance_driven_m() / 1000.0;
  const double mb = static_cast<double>(std::filesystem::file_size(path)) / 1e6;
  std::filesystem::remove(path);

  const MapBuilderTimings& tm = builder.timings();
  std::printf("route:            %.0f m, %zu scans >= 1 m apart (%zu at 10 Hz)\n", builder.distance_driven_m(),
              frames.size(), frames.empty() ? 0 : frames.back() + 1);
  std::printf("mapping:          %.1f scans/s wall (%.2f s), %.1f scans per CPU second on one core (target >= 10)\n",
              frames.size() / build_s, build_s, frames.size() / build_cpu_s);
  std::printf("local clouds:     %zu, median %.0f ms each\n", builder.local_clouds(), median(cloud_ms));
  // Wall clock per stage: on a loaded machine these include waiting; the CPU-second figure
  // above does not. Voxels are summed in accumulate and cropped in crop (voxel stays 0).
  std::printf(
      "stages (sum):     accumulate %.0f, crop %.0f, voxel %.0f, ground %.0f, segment %.0f, describe %.0f, "
      "merge %.0f ms (wall)\n",
      tm.accumulate_ms, tm.crop_ms, tm.voxel_ms, tm.ground_ms, tm.segment_ms, tm.describe_ms, tm.merge_ms);
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  std::printf("peak memory:      %.0f MB resident (scans held in memory for the run included)\n",
              usage.ru_maxrss / 1024.0);
  std::printf("segments:         %zu (from %zu views)\n", builder.segments().size(), builder.extracted_segments());
  std::printf("map file:         %.2f MB, %.2f MB/km, written in %.2f s\n", mb, km > 0 ? mb / km : 0.0, write_s);
  if (!check_voxels) return 0;

  return compare_voxels(config, t, frames, scans);
}
