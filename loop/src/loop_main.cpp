// segmatch-loop: online loop-closure detection over a recorded sequence (paper IV-D). The
// target map is built online from the segments of past local clouds (odometry frame); each
// new local cloud is matched against it. Writes loops.txt, loops.g2o, loops.png and, against
// ground-truth poses, eval.json. With --optimize each loop re-optimises the pose graph
// (posegraph/) and the corrected trajectory is written too.
#include "loop_eval.h"
#include "loop_output.h"
#include "trajectory_output.h"

#include <segmatch/core/loop/loop_closure.h>
#include <segmatch/io/auto_profile.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/pose_io.h>
#include <segmatch/io/sequence.h>
#include <segmatch/posegraph/close_loops.h>

#include <segmatch/cli/progress.h>
#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

struct Options {
  std::string input, config_path, preset, classifier, odometry, truth, out;
  long first = 0, last = -1;
  bool l2 = false, no_eval = false, verbose = false, optimize = false;
  double every_m = 0, exclude_m = -1, exclude_s = -1, radius_m = 0, history_m = 0, min_confidence = -1;
  double max_drift_m = -1, max_drift_deg = -1;  // < 0: not given
  int min_inliers = 0;
  loop::EvalConfig eval;
  posegraph::PoseGraphConfig graph;
  bool revisit_gap_given = false;  // else the gap is the recent past excluded
  bool scan_edges = false;
  posegraph::ScanMatchConfig scan_match;
};

std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read classifier " + path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The config file or preset given, else (and with --preset auto) the parameters derived from
// measuring the scans used (io/auto_profile.h).
io::PipelineConfig pipeline_config(const Options& o, const io::Sequence& seq, size_t first, size_t last) {
  if (!o.config_path.empty()) return io::read_pipeline_config(o.config_path);
  if (!o.preset.empty() && o.preset != "auto") return io::pipeline_preset(o.preset);
  io::PipelineConfig p = io::auto_pipeline_config(io::measure_sequence(seq, first, last));
  std::printf("%s\n", io::describe_profile(p).c_str());
  return p;
}

// The pipeline's stages and loop settings, then the options given.
LoopDetectorConfig detector_config(const Options& o, const io::PipelineConfig& p) {
  LoopDetectorConfig c = io::loop_detector_config(p);
  if (o.radius_m > 0) c.local_cloud.radius_m = o.radius_m;
  if (o.every_m > 0) c.local_cloud_every_m = o.every_m;
  if (o.exclude_m >= 0) c.exclude_recent_distance_m = o.exclude_m;
  if (o.exclude_s >= 0) c.exclude_recent_time_s = o.exclude_s;
  if (o.min_inliers > 0) c.min_inliers = o.min_inliers;
  if (o.min_confidence >= 0) c.min_confidence = static_cast<float>(o.min_confidence);
  if (o.max_drift_m >= 0) c.max_drift_m = o.max_drift_m, c.max_drift_fraction = 0.0;
  if (o.max_drift_deg >= 0) c.max_drift_deg = o.max_drift_deg;
  if (o.history_m > 0)
    c.local_cloud_history_m = o.history_m;
  else
    c.local_cloud_history_m = std::min(c.local_cloud_history_m, c.exclude_recent_distance_m);
  std::printf(
      "%s loop settings: a local cloud every %.1f m, recent past %.0f m, history %.0f m, >= %d inliers, "
      "confidence >= %.2f, drift bound %.1f m%s / %.1f deg%s\n",
      p.preset.c_str(), c.local_cloud_every_m, c.exclude_recent_distance_m, c.local_cloud_history_m, c.min_inliers,
      c.min_confidence, c.max_drift_m,
      c.max_drift_fraction > 0
          ? (" or " + std::to_string(c.max_drift_fraction * 100).substr(0, 4) + " % of the distance driven").c_str()
          : "",
      c.max_drift_deg, c.max_drift_m > 0 || c.max_drift_fraction > 0 ? "" : " (off)");
  return c;
}

// The random forest from --classifier or the default model, else the L2 matcher (also when
// the preset or config asks for it and no --classifier is given).
std::shared_ptr<const RandomForestMatcher> pick_matcher(const Options& o, LoopDetectorConfig& c) {
  std::string path = o.classifier;
  const bool l2 = o.l2 || (path.empty() && c.localizer.matcher.type == MatcherType::kL2);
  if (path.empty() && !l2) path = cli::shipped_model("default-rf.yml");
  if (l2 || path.empty()) {
    if (!l2)
      std::fprintf(
          stderr,
          "segmatch-loop: no classifier (share/segmatch/models/default-rf.yml missing): using the L2 matcher\n");
    c.localizer.matcher.type = MatcherType::kL2;
    c.localizer.matcher.use_shapes = false;
    return nullptr;
  }
  auto rf = std::make_shared<const RandomForestMatcher>(RandomForestMatcher::load(read_file(path)));
  c.localizer.matcher.type = MatcherType::kRandomForest;
  c.localizer.matcher.use_shapes = rf->config().use_shapes;
  std::printf("classifier: %s (%s)\n", path.c_str(), rf->config().use_shapes ? "RF_eigen+shapes" : "RF_eigen");
  return rf;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * v.size()))];
}

// --truth, else the folder's own poses.txt: with --odometry the sequence's poses are the
// odometry, which must not be scored against itself.
Poses reference_poses(const Options& o, const io::Sequence& seq) {
  if (!o.truth.empty()) return io::read_poses(o.truth);
  if (o.odometry.empty()) return seq.poses();
  return io::Sequence::open(o.input).poses();
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path);
}

int run_main(Options o) {
  io::SequenceOptions so;
  so.poses_path = o.odometry;
  const io::Sequence seq = io::Sequence::open(o.input, so);
  const long n = static_cast<long>(seq.size());
  const long last = o.last < 0 ? n - 1 : o.last;
  if (o.first < 0 || o.first > last || last >= n)
    throw std::invalid_argument("--first " + std::to_string(o.first) + " --last " + std::to_string(last) +
                                " outside the sequence's frames 0.." + std::to_string(n - 1));
  LoopDetectorConfig config =
      detector_config(o, pipeline_config(o, seq, static_cast<size_t>(o.first), static_cast<size_t>(last)));
  if (!o.revisit_gap_given) o.eval.min_revisit_gap_m = config.exclude_recent_distance_m;
  const auto classifier = pick_matcher(o, config);
  fs::create_directories(o.out);
  LoopDetector detector(config, classifier);
  std::printf("%s: %ld scans, local cloud every %.1f m (radius %.0f m), recent past %.0f m / %.0f s excluded\n",
              o.input.c_str(), last - o.first + 1, config.local_cloud_every_m, config.local_cloud.radius_m,
              config.exclude_recent_distance_m, config.exclude_recent_time_s);
  posegraph::CloseLoopsOptions co;
  for (long i = o.first; i <= last; ++i) co.frames.push_back(static_cast<size_t>(i));
  co.optimize = o.optimize;
  co.graph = o.graph;
  if (o.scan_edges) co.scan_edges = o.scan_match;
  co.verbose = o.verbose;
  cli::Progress progress("loop", co.frames.size(), "scans");
  co.on_scan = [&progress](size_t done, size_t) { progress.update(done); };
  const posegraph::ClosedLoops r = posegraph::close_loops(seq, config, classifier, co);
  progress.finish();
  std::printf("%zu local clouds, %zu loops, %zu map segments; per local cloud %.0f ms median, %.0f ms p90\n",
              r.processed.size(), r.loops.size(), r.map_odom.size(), percentile(r.step_ms, 0.5),
              percentile(r.step_ms, 0.9));
  const fs::path out(o.out);
  loop::write_loops_txt((out / "loops.txt").string(), r.loops);
  loop::write_g2o((out / "loops.g2o").string(), r.frames, r.T_odom_sensor, r.graph);
  Poses reference;
  std::vector<bool> correct;
  nlohmann::json eval_json;
  if (!o.no_eval) {
    const Poses truth = reference_poses(o, seq);
    const loop::Evaluation e = loop::evaluate(r.loops, r.processed, truth, static_cast<size_t>(o.first), o.eval);
    for (const loop::LoopScore& s : e.scores) correct.push_back(s.correct);
    for (size_t f : r.frames) reference.push_back(truth.at(f));
    loop::print_summary(e, o.eval);
    eval_json = nlohmann::json::parse(loop::to_json(e, o.eval));
    loop::write_curve_png((out / "precision_recall.png").string(), e.curve, o.eval.max_rotation_error_deg);
  }
  loop::write_png((out / "loops.png").string(), r.frames, r.T_odom_sensor, r.processed, r.loops, correct);
  std::string written = "loops.txt,loops.g2o,loops.png,odometry.tum";
  // The odometry of every processed frame, for evo (`evo_traj tum odometry.tum`).
  std::vector<double> times;
  for (size_t f : r.frames) times.push_back(seq.times()[f]);
  loop::write_tum((out / "odometry.tum").string(), times, r.T_odom_sensor);
  if (o.optimize) {
    const loop::TrajectorySummary t = loop::summarize(r, reference);
    loop::print_summary(t, r.loops);
    io::write_kitti_poses((out / "poses_corrected.txt").string(), r.T_corrected_sensor);
    loop::write_tum((out / "poses_corrected.tum").string(), times, r.T_corrected_sensor);
    loop::write_g2o((out / "optimized.g2o").string(), r.frames, r.T_corrected_sensor, r.graph);
    loop::write_trajectory_png((out / "trajectory.png").string(), r, reference, t);
    written += ",poses_corrected.txt,poses_corrected.tum,optimized.g2o,trajectory.png";
    if (!o.no_eval) eval_json["trajectory"] = loop::to_json(t, r.loops);
  }
  if (!o.no_eval) {
    write_text((out / "eval.json").string(), eval_json.dump(2) + "\n");
    written += ",eval.json,precision_recall.png";
  }
  std::printf("wrote %s/{%s}\n", o.out.c_str(), written.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Online loop-closure detection with SegMatch (the target map is built while driving)"};
  Options o;
  app.add_option("--input", o.input, "sequence folder (KITTI velodyne/ or PCD keyframes scans/)")->required();
  auto* config_opt = app.add_option("--config", o.config_path, "pipeline config JSON");
  app.add_option(
         "--preset", o.preset,
         "pipeline preset: auto (default: measured from the input), kitti-hdl64, sparse-keyframes, livox-keyframes")
      ->excludes(config_opt);
  app.add_option("--classifier", o.classifier, "random forest model (default: maps/models/default-rf.yml if present)");
  app.add_flag("--l2", o.l2, "use the L2 feature-distance matcher instead of a random forest");
  app.add_option("--odometry", o.odometry,
                 "odometry poses (KITTI 12 numbers or TUM 8 columns) instead of the sequence's poses.txt");
  app.add_option("--truth", o.truth,
                 "ground-truth T_world_lidar poses, KITTI 12 numbers or TUM 8 columns (default: the sequence's "
                 "poses.txt, also with --odometry)");
  app.add_flag("-v,--verbose", o.verbose, "print what each local cloud did");
  app.add_flag("--no-eval", o.no_eval, "do not evaluate (the input has no ground truth)");
  app.add_flag("--optimize", o.optimize,
               "optimise the pose graph at each loop (Ceres, robust loop edges) and write the corrected "
               "trajectory (KITTI, TUM), optimized.g2o, trajectory.png and its error in eval.json");
  app.add_option("--odometry-sigma-fraction", o.graph.odometry_sigma_fraction,
                 "--optimize: odometry translation sigma as a fraction of each step (default 0.02)");
  app.add_option("--odometry-lateral-ratio", o.graph.odometry_lateral_ratio,
                 "--optimize: sideways and vertical sigma relative to along-track (default 1)");
  app.add_option("--gravity-sigma-deg", o.graph.gravity_sigma_deg,
                 "--optimize: hold roll and pitch to the odometry's within this sigma (default 0: off)");
  app.add_option(
      "--bias-stretch-m", o.graph.bias_stretch_m,
      "--optimize: estimate the odometry's yaw-rate and climb bias per stretch of this length (default 100; 0: off)");
  app.add_flag("--scan-edges", o.scan_edges,
               "--optimize: register each scan onto the previous ones (ICP) and add the step as an edge: for odometry "
               "that errs in scale or yaw rate (wheels), which loops cannot correct");
  app.add_option("--scan-sigma-m", o.graph.scan_sigma_m,
                 "--scan-edges: translation sigma of a scan edge (default 0.01)");
  app.add_option("--scan-sigma-deg", o.graph.scan_sigma_deg, "--scan-edges: rotation sigma of a scan edge (default 1)");
  app.add_option("--scan-voxel-m", o.scan_match.voxel_m, "--scan-edges: scans thinned to this voxel (default 0.3)");
  app.add_option("--scan-target-scans", o.scan_match.target_scans,
                 "--scan-edges: a scan is registered onto this many previous ones (default 3)");
  app.add_option("--scan-max-range-m", o.scan_match.max_range_m,
                 "--scan-edges: points farther are not used (default 60)");
  app.add_option("--first", o.first, "first frame (default 0)");
  app.add_option("--last", o.last, "last frame (default: the sequence's last)");
  app.add_option("--every-m", o.every_m, "local cloud every this many metres (default 10; livox-keyframes: 1)");
  app.add_option("--radius-m", o.radius_m, "local cloud radius (default: the config's)");
  app.add_option("--exclude-m", o.exclude_m, "recent past excluded from matching, metres driven (default 150)");
  app.add_option("--exclude-s", o.exclude_s, "recent past excluded from matching, seconds (default 0)");
  app.add_option("--history-m", o.history_m,
                 "query local cloud holds at most this much driving (default min(120, exclude))");
  app.add_option("--min-confidence", o.min_confidence, "minimum confidence of a loop, 0..1 (default 0.6)");
  app.add_option("--min-inliers", o.min_inliers, "minimum inlier matches of a loop (default 5)");
  app.add_option("--max-drift-m", o.max_drift_m,
                 "accept loops only within this of the odometry's own position (default 0: anywhere)")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--max-drift-deg", o.max_drift_deg, "with --max-drift-m: heading drift bound, degrees (default 5)")
      ->check(CLI::Range(0.0, 180.0));
  app.add_option("--revisit-radius-m", o.eval.revisit_radius_m,
                 "evaluation: a revisit is within this of an earlier pose");
  app.add_option("--revisit-gap-m", o.eval.min_revisit_gap_m,
                 "evaluation: ... driven at least this long before (default: --exclude-m)");
  cli::add_output_option(app, o.out, "output folder, required");
  cli::add_version_flag(app, "segmatch-loop");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (o.scan_edges && !o.optimize) {
    std::fprintf(stderr, "segmatch-loop: --scan-edges needs --optimize (the edges only matter to the optimiser)\n");
    return 2;
  }
  if (const int status = cli::require_output("segmatch-loop", o.out); status >= 0) return status;
  try {
    o.revisit_gap_given = app.count("--revisit-gap-m") > 0;
    return run_main(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-loop: %s\n", e.what());
    return 1;
  }
}
