// segmatch-sim: generates an urban world, drives it twice and writes KITTI-layout data with
// exact ground truth (poses, per-point labels, revisits) and pictures; optionally also the
// keyframes a SLAM front end would write (PCD scans, poses, drifting odometry).
#include "segmatch/cli/progress.h"
#include "segmatch/sim/dataset.h"

#include <segmatch/io/bag.h>
#include <segmatch/io/sequence.h>

#include <segmatch/cli/tool.h>

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
  if (!force) throw std::runtime_error(out.string() + " is not empty: pass --force to replace the dataset in it");
  for (const char* sub : {"sequences", "keyframes", "ground_truth", "world.png", "scan.png", "dataset.json"})
    fs::remove_all(out / sub);
}

// The keyframe export's options; the drift is given in percent, the library takes a fraction.
struct KeyframeOptions {
  sim::KeyframeConfig config;
  double odom_drift_pct = config.odom_scale_error * 100.0;
  sim::KeyframeConfig resolved() const {
    sim::KeyframeConfig c = config;
    c.odom_scale_error = odom_drift_pct / 100.0;
    return c;
  }
};

void add_keyframe_options(CLI::App& app, KeyframeOptions* k) {
  app.add_option("--keyframes-every-m", k->config.every_m,
                 "also write SLAM-style keyframes to OUT/keyframes/{00,01}: one each time the sensor moved this far "
                 "(0: none, the default)");
  app.add_option("--keyframe-leaf-m", k->config.leaf_m, "voxel size of the keyframe downsampling (default 0.2)");
  app.add_option("--keyframe-frames", k->config.frames,
                 "scans integrated per keyframe (default: 5 for livox-avia, 1 for spinning sensors)");
  app.add_option("--odom-drift-pct", k->odom_drift_pct,
                 "odom_poses.txt (sequences and keyframes) reads every step this % too long (default 0.2; 0 "
                 "with the four below 0: equal to poses.txt)");
  app.add_option("--odom-yaw-drift-deg-per-m", k->config.odom_yaw_drift_deg_per_m,
                 "and turns this much left per metre (default 0.003)");
  app.add_option("--odom-climb-m-per-m", k->config.odom_climb_m_per_m, "and climbs this much per metre (default 0)");
  app.add_option(
      "--odom-heading-walk", k->config.odom_heading_walk_deg_per_sqrt_m,
      "and its heading takes a random walk of this many deg per sqrt(m) driven (default 0.04: LiDAR-inertial "
      "odometry, ~0.4 deg per 100 m; 0: none)");
  app.add_option("--odom-pitch-walk", k->config.odom_pitch_walk_deg_per_sqrt_m,
                 "and its pitch one of this many deg per sqrt(m) (default 0.02; 0: none)");
  app.add_option("--odom-seed", k->config.odom_seed,
                 "seed of those random walks (default 1; mixed with --seed per sequence)");
}

void print_summary(const sim::DatasetConfig& config, const sim::DatasetSummary& s, const std::string& out) {
  std::printf("world:      %zu objects, %zu primitives, %.1f km of streets\n", s.objects, s.primitives,
              s.street_length_m / 1000.0);
  std::printf("sequence 00: %zu scans, %.0f m driven (map run)\n", s.scans[0], s.length_m[0]);
  std::printf("sequence 01: %zu scans, %.0f m driven; %zu scans within 5 m of sequence 00, %zu more than 30 m away\n",
              s.scans[1], s.length_m[1], s.revisit_frames, s.unmapped_frames);
  std::printf("points:     %zu (%.1f per scan)\n", s.points,
              static_cast<double>(s.points) / std::max<size_t>(1, s.scans[0] + s.scans[1]));
  std::printf("time:       %s\n", cli::Progress::format_duration(s.seconds).c_str());
  const bool keyframes = config.keyframes.every_m > 0;
  if (keyframes)
    std::printf("keyframes:  %zu + %zu (%.1f points each), every %.1f m\n", s.keyframes[0], s.keyframes[1],
                static_cast<double>(s.keyframe_points) / std::max<size_t>(1, s.keyframes[0] + s.keyframes[1]),
                config.keyframes.every_m);
  std::printf("output:     %s/sequences/{00,01}, %s/ground_truth\n", out.c_str(), out.c_str());
  if (keyframes) std::printf("            %s/keyframes/{00,01}\n", out.c_str());
  if (config.write_images) std::printf("pictures:   %s/world.png, %s/scan.png\n", out.c_str(), out.c_str());
}

// Sequence 00 as a ROS 2 bag (io::write_sequence_bag), with progress.
void write_bag(const std::string& out, const std::string& bag_path) {
  const io::Sequence seq = io::Sequence::open(out + "/sequences/00");
  cli::Progress progress("bag", seq.size(), "scans");
  io::write_sequence_bag(seq, bag_path, {}, [&](size_t done, size_t) { progress.update(done); });
  progress.finish();
  std::printf("bag:        %s (%zu scans; /points, /odom, /tf)\n", bag_path.c_str(), seq.size());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Generate a simulated urban LiDAR dataset (two traversals, KITTI layout, exact ground truth)"};
  std::string preset = "demo", out, sensor, route_00 = "random";
  uint64_t seed = 1;
  double first_m = 0, second_m = 0, speed_mps = 0;
  KeyframeOptions keyframes;
  int threads = 0;
  bool force = false, no_labels = false, no_images = false;
  std::string bag_path;
  app.add_option("--preset", preset, "tiny (seconds, tests), demo (~2 km), city (10+ km of streets)")
      ->check(CLI::IsMember(sim::dataset_preset_names()));
  app.add_option("--seed", seed, "world seed: same seed, same bytes");
  cli::add_output_option(app, out, "output folder (default: out/sim-<preset>-<seed>)");
  app.add_option("--sensor", sensor,
                 "hdl64e (default), hdl32e, vlp16, os1-64, os0-64 (+-45 deg, carried at 1.5 m) or livox-avia (rosette "
                 "scan in a 70.4 x 77.2 deg forward cone, "
                 "24000 points per 0.1 s frame, never repeating; carried at 1.0 m)");
  app.add_option("--speed-mps", speed_mps, "cruise speed of both traversals (default 10; e.g. 1.5 for walking)")
      ->check(CLI::Range(0.3, 40.0));
  add_keyframe_options(app, &keyframes);
  app.add_option("--route-00", route_00,
                 "route of the first traversal: random (default) or loop (around the city and along its first "
                 "streets again, for loop closure; ignores --length-00-m)")
      ->check(CLI::IsMember({"random", "loop"}));
  app.add_option("--length-00-m", first_m, "route length of the first traversal (default from preset)");
  app.add_option("--length-01-m", second_m, "route length of the second traversal (default from preset)");
  app.add_option("--threads", threads, "worker threads (0: one per core)");
  app.add_flag("--force", force, "replace an existing dataset in the output folder");
  app.add_flag("--no-labels", no_labels, "do not write per-point labels");
  app.add_flag("--no-images", no_images, "do not draw world.png and scan.png");
  app.add_option("--bag", bag_path,
                 "also write sequence 00 (the mapping drive) as a ROS 2 bag, MCAP with zstd chunks: /points "
                 "(sensor_msgs/msg/PointCloud2), /odom (nav_msgs/msg/Odometry) and /tf, frames map and lidar");
  cli::add_version_flag(app, "segmatch-sim");
  SEGMATCH_CLI_PARSE(app, argc, argv);

  try {
    sim::DatasetConfig config = sim::dataset_preset(preset, seed);
    if (!sensor.empty()) config.use_sensor(sensor);
    if (speed_mps > 0) config.drive_first.cruise_speed_mps = config.drive_second.cruise_speed_mps = speed_mps;
    config.keyframes = keyframes.resolved();
    if (first_m > 0) config.first_length_m = first_m;
    config.first_route = route_00;
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
    print_summary(config, s, out);
    if (!bag_path.empty()) write_bag(out, bag_path);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-sim: error: %s\n", e.what());
    return 1;
  }
}
