// segmatch-sim: generates an urban world, drives it twice and writes KITTI-layout data with
// exact ground truth (poses, per-point labels, revisits) and pictures.
#include "segmatch/cli/progress.h"
#include "segmatch/sim/dataset.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <memory>

namespace fs = std::filesystem;
using namespace segmatch;

namespace {

// Turns the library's progress callbacks into one progress bar per stage.
class StageProgress {
 public:
  void operator()(const std::string& stage, size_t done, size_t total) {
    if (stage != stage_) {
      bar_.reset();
      stage_ = stage;
      if (total <= 1) {
        std::fprintf(stderr, "[%s] ...\n", stage.c_str());
        return;
      }
      bar_ = std::make_unique<cli::Progress>(stage, total, "scans");
    }
    if (bar_) bar_->update(done);
  }

 private:
  std::string stage_;
  std::unique_ptr<cli::Progress> bar_;
};

void clear_previous_output(const fs::path& out, bool force) {
  if (!fs::exists(out)) return;
  if (!fs::is_directory(out)) throw std::runtime_error(out.string() + " exists and is not a folder");
  if (fs::is_empty(out)) return;
  if (!force)
    throw std::runtime_error(out.string() + " is not empty: pass --force to replace the dataset in it");
  for (const char* sub : {"sequences", "ground_truth", "world.png", "scan.png", "dataset.json"})
    fs::remove_all(out / sub);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Generate a simulated urban LiDAR dataset (two traversals, KITTI layout, exact ground truth)"};
  std::string preset = "demo", out, sensor;
  uint64_t seed = 1;
  double first_m = 0, second_m = 0;
  int threads = 0;
  bool force = false, no_labels = false, no_images = false;
  app.add_option("--preset", preset, "tiny (seconds, tests), demo (~2 km), city (10+ km of streets)")
      ->check(CLI::IsMember(sim::dataset_preset_names()));
  app.add_option("--seed", seed, "world seed: same seed, same bytes");
  app.add_option("-o,--out", out, "output folder (default: out/sim-<preset>-<seed>)");
  app.add_option("--sensor", sensor, "hdl64e (default), vlp16 or os1-64");
  app.add_option("--length-00-m", first_m, "route length of the first traversal (default from preset)");
  app.add_option("--length-01-m", second_m, "route length of the second traversal (default from preset)");
  app.add_option("--threads", threads, "worker threads (0: one per core)");
  app.add_flag("--force", force, "replace an existing dataset in the output folder");
  app.add_flag("--no-labels", no_labels, "do not write per-point labels");
  app.add_flag("--no-images", no_images, "do not draw world.png and scan.png");
  CLI11_PARSE(app, argc, argv);

  try {
    sim::DatasetConfig config = sim::dataset_preset(preset, seed);
    if (!sensor.empty()) config.sensor = sensor;
    if (first_m > 0) config.first_length_m = first_m;
    if (second_m > 0) config.second_length_m = second_m;
    config.threads = threads;
    config.write_labels = !no_labels;
    config.write_images = !no_images;
    config.validate();
    if (out.empty()) out = "out/sim-" + preset + "-" + std::to_string(seed);
    clear_previous_output(out, force);

    std::fprintf(stderr, "segmatch-sim: preset %s, seed %llu, sensor %s -> %s\n", preset.c_str(),
                 static_cast<unsigned long long>(seed), config.sensor.c_str(), out.c_str());
    StageProgress progress;
    const sim::DatasetSummary s = sim::generate_dataset(config, out, std::ref(progress));
    std::printf("world:      %zu objects, %zu primitives, %.1f km of streets\n", s.objects, s.primitives,
                s.street_length_m / 1000.0);
    std::printf("sequence 00: %zu scans, %.0f m driven (map run)\n", s.scans[0], s.length_m[0]);
    std::printf("sequence 01: %zu scans, %.0f m driven; %zu scans within 5 m of sequence 00, %zu more than 30 m away\n",
                s.scans[1], s.length_m[1], s.revisit_frames, s.unmapped_frames);
    std::printf("points:     %zu (%.1f per scan)\n", s.points,
                static_cast<double>(s.points) / std::max<size_t>(1, s.scans[0] + s.scans[1]));
    std::printf("time:       %s\n", cli::Progress::format_duration(s.seconds).c_str());
    std::printf("output:     %s/sequences/{00,01}, %s/ground_truth\n", out.c_str(), out.c_str());
    if (config.write_images) std::printf("pictures:   %s/world.png, %s/scan.png\n", out.c_str(), out.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-sim: error: %s\n", e.what());
    return 1;
  }
}
