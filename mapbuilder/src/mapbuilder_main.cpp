// segmatch-mapbuilder: builds a segment map (SQLite) from a mapping traversal.
#include "build_map.h"

#include <segmatch/io/error.h>
#include <segmatch/storage/map_types.h>

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>

#include <csignal>
#include <cstdio>

using namespace segmatch;

namespace {

volatile std::sig_atomic_t g_stop_signal = 0;

// The build loop polls the flag and unwinds normally, so the MapWriter's destructor deletes
// its temporary file. SA_RESETHAND: a second Ctrl-C kills at once (leaving at most the
// temporary file, never a half-written map at the target).
void install_signal_handlers() {
  struct sigaction action {};
  action.sa_handler = [](int signal) { g_stop_signal = signal; };
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESETHAND;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

int fail(int code, const std::string& message) {
  std::fprintf(stderr, "segmatch-mapbuilder: error: %s\n", message.c_str());
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Build a SegMatch segment map (one SQLite file) from a mapping traversal"};
  mapbuilder::BuildOptions o;
  size_t first = 0, last = 0;
  app.add_option(
         "-i,--input", o.input,
         "sequence folder: KITTI (velodyne/, poses.txt, calib.txt) or PCD keyframes; or a ROS 2 bag (.mcap, .db3, "
         "or a rosbag2 folder)")
      ->required();
  cli::add_bag_options(app, o.bag.points_topic, o.bag.pose_topic, o.bag.map_frame, o.bag.sensor_frame);
  auto* output = app.add_option("-o,--output", o.output, "map file to write (e.g. map.sqlite)");
  auto* config = app.add_option("--config", o.config_path, "pipeline config JSON (see io/pipeline_config.h)");
  app.add_option(
         "--preset", o.preset,
         "pipeline preset: auto (default: measured from the input), kitti-hdl64, sparse-keyframes or livox-keyframes")
      ->excludes(config);
  auto* print = app.add_flag("--print-config", o.print_config,
                             "print the chosen pipeline config as JSON (to reuse with --config) and build nothing");
  output->excludes(print);
  auto* first_opt = app.add_option("--first", first, "first scan index (default 0)");
  auto* last_opt = app.add_option("--last", last, "last scan index, inclusive (default: the last scan)");
  app.add_option("--stride", o.stride, "use every N-th scan of the range (default 1)");
  app.add_option("--map-every-m", o.map_every_m, "distance driven between two segmented local clouds (default 5 m)");
  auto* model = app.add_option("--classifier", o.classifier_path,
                               "classifier model to store in the map (default: maps/models/default-rf.yml if present)");
  app.add_flag("--no-classifier", o.no_classifier, "store no classifier")->excludes(model);
  app.add_option("--name", o.name, "map name (default: the output file's stem)");
  app.add_flag("--force", o.force, "replace an existing map file");
  app.add_option(
      "--odometry", o.odometry_path,
      "poses (KITTI 12 numbers as poses.txt, or TUM 8 columns) to build from instead of poses.txt (a bag: TUM, "
      "matched by time)");
  app.add_flag("--close-loops", o.close_loops,
               "the poses are a drifting odometry: detect loops and optimise the pose graph first, and build "
               "the map on the corrected poses");
  app.add_flag("--scan-edges", o.scan_edges,
               "with --close-loops: also register each scan onto the previous ones (ICP), for odometry that errs "
               "in scale or yaw rate (wheels), which loops cannot correct");
  app.add_option("--min-segments-per-km", o.min_segments_per_km,
                 "refuse (write nothing) when the map would hold fewer segments per km driven; a map with no "
                 "segments is always refused")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  cli::add_version_flag(app, "segmatch-mapbuilder");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (!o.print_config && o.output.empty()) {
    std::fprintf(stderr, "segmatch-mapbuilder: error: --output is required\n");
    return 2;
  }
  if (o.scan_edges && !o.close_loops) {
    std::fprintf(stderr, "segmatch-mapbuilder: error: --scan-edges needs --close-loops\n");
    return 2;
  }
  if (first_opt->count()) o.first = first;
  if (last_opt->count()) o.last = last;

  install_signal_handlers();
  try {
    return mapbuilder::build_map(o, &g_stop_signal);
  } catch (const mapbuilder::UsageError& e) {
    return fail(2, e.what());
  } catch (const io::IoError& e) {
    return fail(1, e.what());
  } catch (const storage::StorageError& e) {
    return fail(1, e.what());
  } catch (const std::exception& e) {
    return fail(1, e.what());
  }
}
