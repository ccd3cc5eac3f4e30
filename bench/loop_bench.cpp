// segmatch-bench-loop: time of online loop-closure detection per local cloud (LoopDetector::
// process on the steps that segment and match, paper IV-D) on a simulated HDL-64E drive, on the
// calling thread (one core), against the real-time budget: a local cloud every N metres at
// 10 m/s leaves N / 10 s per local cloud. Scans are simulated between steps, not timed. Also
// prints the time of the steps that only accumulate a scan.
#include "segmatch/core/loop/loop_closure.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/traversal.h"
#include "segmatch/sim/world.h"

#include <CLI/CLI.hpp>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

using namespace segmatch;

namespace {

double thread_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Per-local-cloud time of online loop-closure detection on a simulated HDL-64E drive"};
  std::string preset = "demo";
  uint64_t seed = 1;
  double every_m = 10.0, length_m = 600.0, speed_mps = 10.0;
  int threads = 2;
  app.add_option("--preset", preset, "simulated city: tiny, demo, city");
  app.add_option("--seed", seed, "city seed");
  app.add_option("--length-m", length_m, "metres of the first traversal to drive");
  app.add_option("--every-m", every_m, "local cloud every this many metres");
  app.add_option("--speed-mps", speed_mps, "speed for the real-time budget");
  app.add_option("--sim-threads", threads, "threads simulating scans (between timed steps)");
  CLI11_PARSE(app, argc, argv);
  try {
    sim::DatasetConfig dc = sim::dataset_preset(preset, seed);
    dc.first_length_m = length_m;
    const sim::World world = sim::generate_world(dc.world);
    Rng rng(mix_seed(seed, 0x7a5e));
    const sim::Traversal t = sim::drive(world, sim::plan_route(world.streets, length_m, rng), dc.drive_first);
    const sim::RayCaster caster(world.scene());
    LoopDetectorConfig config;  // the paper's parameters, L2 matcher (no classifier needed)
    config.local_cloud_every_m = every_m;
    config.localizer.matcher.type = MatcherType::kL2;
    config.localizer.matcher.use_shapes = false;
    LoopDetector detector(config);
    std::vector<size_t> frames;  // a scan every metre (the local cloud keeps no others)
    for (size_t i = 0; i < t.size(); ++i)
      if (frames.empty() ||
          (t.T_world_lidar[i].translation() - t.T_world_lidar[frames.back()].translation()).norm() >= 1.0)
        frames.push_back(i);
    std::vector<double> wall, cpu, accumulate, segment, match;
    size_t loops = 0;
    for (size_t b = 0; b < frames.size(); b += 32) {
      const std::vector<size_t> batch(frames.begin() + b, frames.begin() + std::min(frames.size(), b + 32));
      const auto scans = sim::simulate_scans(caster, sim::hdl64e(), t.T_world_lidar, batch, threads);
      for (size_t k = 0; k < batch.size(); ++k) {
        const double c0 = thread_cpu_ms();
        const auto w0 = std::chrono::steady_clock::now();
        const LoopStep s = detector.process(scans[k].points, t.T_world_lidar[batch[k]], batch[k], t.times_s[batch[k]]);
        const double w = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - w0).count();
        if (!s.processed) {
          accumulate.push_back(w);
          continue;
        }
        wall.push_back(w);
        cpu.push_back(thread_cpu_ms() - c0);
        segment.push_back(s.timings.voxel_ms + s.timings.ground_ms + s.timings.segment_ms + s.timings.describe_ms);
        match.push_back(s.timings.retrieve_ms + s.timings.classify_ms + s.timings.verify_ms + s.timings.refine_ms);
        loops += s.loop.has_value();
      }
      std::fprintf(stderr, "\r%zu / %zu scans", std::min(frames.size(), b + 32), frames.size());
    }
    const double budget_ms = every_m / speed_mps * 1e3;
    std::printf("\n%s seed %llu: %.0f m driven, %zu local clouds (every %.0f m), %zu map segments, %zu loops\n",
                preset.c_str(), static_cast<unsigned long long>(seed), t.length_m(), wall.size(), every_m,
                detector.map_size(), loops);
    std::printf("per local cloud (wall): median %.0f ms, p90 %.0f ms, max %.0f ms; thread CPU median %.0f ms\n",
                quantile(wall, 0.5), quantile(wall, 0.9), quantile(wall, 1.0), quantile(cpu, 0.5));
    std::printf("  segmentation+description median %.0f ms, matching+verification+refinement median %.0f ms\n",
                quantile(segment, 0.5), quantile(match, 0.5));
    std::printf("scan accumulation (other steps): median %.1f ms, p90 %.1f ms\n", quantile(accumulate, 0.5),
                quantile(accumulate, 0.9));
    std::printf("real-time budget at %.0f m/s: %.0f ms per local cloud -> p90 uses %.0f %%\n", speed_mps, budget_ms,
                100.0 * quantile(wall, 0.9) / budget_ms);
    // Keeping up overall: every call (accumulating ones too) against the time the drive takes.
    double busy_ms = 0;
    for (double w : wall) busy_ms += w;
    for (double w : accumulate) busy_ms += w;
    const double drive_ms = t.length_m() / speed_mps * 1e3;
    std::printf("whole drive: %.1f s of processing for %.1f s of driving at %.0f m/s (%.0f %% of one core)\n",
                busy_ms / 1e3, drive_ms / 1e3, speed_mps, 100.0 * busy_ms / drive_ms);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-bench-loop: %s\n", e.what());
    return 1;
  }
}
