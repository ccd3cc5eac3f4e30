// segmatch-bench-sim: how fast the simulator produces LiDAR scans on ONE core.
// Target (issue #2): at least 10 simulated HDL-64E scans per second, i.e. faster than the
// real sensor. Prints medians over scans taken along the demo world's first traversal.
#include "segmatch/sim/dataset.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

using namespace segmatch;
using Clock = std::chrono::steady_clock;

namespace {
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))];
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Benchmark the LiDAR simulator on one core"};
  std::string preset = "demo";
  std::vector<std::string> sensors = {"hdl64e", "os1-64", "vlp16"};
  int scans = 60;
  app.add_option("--preset", preset, "world preset (tiny, demo, city)");
  app.add_option("--sensors", sensors, "sensor models to time");
  app.add_option("--scans", scans, "scans per sensor, spread along the first traversal")->check(CLI::Range(5, 10000));
  CLI11_PARSE(app, argc, argv);

  const sim::DatasetConfig c = sim::dataset_preset(preset, 1);
  auto t0 = Clock::now();
  const sim::World world = sim::generate_world(c.world);
  const double world_s = seconds_since(t0);
  Rng rng(mix_seed(c.world.seed, 0x7a5e));
  const sim::Traversal trav = sim::drive(world, sim::plan_route(world.streets, c.first_length_m, rng), c.drive_first);
  const sim::Scene scene = world.scene();
  t0 = Clock::now();
  const sim::RayCaster caster(scene);
  const double bvh_s = seconds_since(t0);
  std::printf("world %s: %.1f km of streets, %zu objects, %zu primitives; generation %.2f s, BVH build %.3f s\n",
              preset.c_str(), world.streets.total_length_m() / 1000.0, world.objects.size(), scene.size(), world_s,
              bvh_s);
  std::printf("%-8s %8s %10s %12s %12s %12s %10s\n", "sensor", "scans", "rays/scan", "median ms", "p90 ms", "scans/s",
              "Mrays/s");
  for (const std::string& name : sensors) {
    const sim::LidarModel model = sim::lidar_model_by_name(name);
    std::vector<double> ms;
    size_t points = 0;
    for (int k = 0; k < scans; ++k) {
      const size_t frame = static_cast<size_t>(k) * (trav.size() - 1) / (scans - 1);
      t0 = Clock::now();
      const sim::SimulatedScan s = sim::simulate_scan(caster, model, trav.T_world_lidar[frame], k);
      ms.push_back(1000.0 * seconds_since(t0));
      points += s.points.size();
    }
    const double median = percentile(ms, 0.5);
    std::printf("%-8s %8d %10zu %12.1f %12.1f %12.1f %10.2f   (%.0f points/scan)\n", name.c_str(), scans,
                model.rays_per_scan(), median, percentile(ms, 0.9), 1000.0 / median,
                model.rays_per_scan() / median / 1000.0, static_cast<double>(points) / scans);
  }
  std::printf("target: HDL-64E >= 10 scans/s on one core (the sensor's own rate)\n");
  return 0;
}
