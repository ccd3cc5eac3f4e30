// segmatch-eval: how well localization works, in the paper's terms.
//   segmatch-eval localize   replay a traversal against a map (in-process or through a server)
//   segmatch-eval classifier ROC of L2, RF_eigen, RF_eigen+shapes on a held-out simulated city
//                            (or, with --real, on the held-out stretches of a real recording)
#include "segmatch/api/client.h"
#include "segmatch/eval/funnel.h"
#include "segmatch/eval/localization_run.h"
#include "segmatch/eval/real_pairs.h"
#include "segmatch/eval/roc.h"
#include "segmatch/io/auto_profile.h"
#include "segmatch/io/error.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/server/map_service.h"
#include "segmatch/sim/city.h"
#include "segmatch/vehicle/segment_query.h"

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

// --segments: the vehicle segments and describes each query itself (segmatch_vehicle) and
// sends LOCALIZE_SEGMENTS; its own time and the request sizes are reported apart. With a
// tracker's prior (narrow enough for registration) it first sends the tracking request
// (revision 11: no segment points, the newest scans thinned) and the full one only when that
// comes back TRACKING_LOST; both requests' bytes and server times count.
struct SegmentsSide {
  std::unique_ptr<vehicle::SegmentQuery> query;
  bool track = true;
  std::vector<double> vehicle_ms, request_bytes, tracking_bytes;
  size_t tracked = 0, lost = 0;
  api::LocalizeSegmentsRequest make(const api::LocalizeRequest& r) {
    ModuleTimings t;
    api::LocalizeSegmentsRequest s = query->make_request(r, &t);
    vehicle_ms.push_back(t.total_ms);
    return s;
  }
  template <typename Send>
  api::LocalizeReply exchange(const api::LocalizeRequest& r, Send&& send) {
    const api::LocalizeSegmentsRequest full = make(r);
    if (!track) {
      request_bytes.push_back(static_cast<double>(api::encode(full).size()));
      return send(full);
    }
    const vehicle::SegmentQuery::TrackedReply t = query->localize_tracking_first(full, send);
    request_bytes.push_back(static_cast<double>(t.request_bytes));
    if (t.tracking) {
      ++tracked;
      lost += t.lost;
      tracking_bytes.push_back(static_cast<double>(t.tracking_bytes));
    }
    return t.reply;
  }
  void print() const {
    if (!query || vehicle_ms.empty()) return;
    std::printf(
        "vehicle side (--segments): median %.1f ms segmenting and describing per query, median request %.0f bytes\n",
        eval::distribution_of(vehicle_ms).median, eval::distribution_of(request_bytes).median);
    if (tracked)
      std::printf(
          "tracking requests (no segment points, newest scans thinned): %zu sent, median %.0f bytes; %zu came back "
          "TRACKING_LOST and were resent in full\n",
          tracked, eval::distribution_of(tracking_bytes).median, lost);
  }
};

// The map's places are described in the background after loading (a city's take seconds on
// one of the two cores); the queries' server times are those of a server past that, so the
// replay starts when they are ready.
void wait_for_places(const server::LoadedMap& loaded) {
  const auto start = std::chrono::steady_clock::now();
  if (!loaded.localizer->places()) return;
  std::fprintf(stderr, "places: %zu described in %.1f s (the replay starts after them)\n",
               loaded.localizer->places()->size(),
               std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

int run_localize(const eval::LocalizationRunConfig& config, const std::string& server, const std::string& token_file,
                 const std::string& out_dir, bool segments, bool track_surfaces, const server::MapLoadOptions& load) {
  eval::LocalizeFn localize;
  std::shared_ptr<const server::LoadedMap> loaded;
  std::unique_ptr<api::Client> client;
  SegmentsSide side;
  side.track = track_surfaces;
  if (server.empty()) {
    loaded = server::load_map(config.map_path, load);
    for (const std::string& w : loaded->warnings) std::fprintf(stderr, "warning: %s\n", w.c_str());
    wait_for_places(*loaded);
    if (segments) {
      side.query = std::make_unique<vehicle::SegmentQuery>(server::info_of(*loaded).parameters_json);
      localize = [&](const api::LocalizeRequest& r) {
        return side.exchange(r, [&](const api::LocalizeSegmentsRequest& s) {
          if (const auto refused = server::refuse_segments(*loaded, s)) throw std::runtime_error(refused->message);
          return server::localize_segments_request(*loaded, s);
        });
      };
    } else {
      localize = [&](const api::LocalizeRequest& r) { return server::localize_request(*loaded, r); };
    }
  } else {
    const cli::HostPort where = cli::parse_server(server);
    api::ClientOptions options;
    options.token = cli::read_token_file(token_file);
    client = std::make_unique<api::Client>(where.host, where.port, options);
    if (segments) {
      side.query = std::make_unique<vehicle::SegmentQuery>(vehicle::SegmentQuery::from_info(client->info()));
      localize = [&](const api::LocalizeRequest& r) {
        return side.exchange(r, [&](const api::LocalizeSegmentsRequest& s) { return client->localize_segments(s); });
      };
    } else {
      localize = [&](const api::LocalizeRequest& r) { return client->localize(r); };
    }
  }
  const eval::LocalizationRun run = eval::run_localization(config, localize);
  eval::print_summary(run);
  side.print();
  if (!out_dir.empty()) {
    eval::write_localization_report(run, out_dir);
    std::printf("report: %s/{localization.json, estimated.tum, reference.tum, trajectory.png, px.png, errors.png}\n",
                out_dir.c_str());
  }
  return 0;
}

struct ClassifierOptions {
  std::string preset = "tiny", config_path, model_shapes, model_eigen, out_dir, sensor = "hdl64e", real_dir;
  uint64_t seed = 104;
};

RandomForestMatcher load_model(const std::string& path) {
  return RandomForestMatcher::load(io::read_file_bytes(path, "model file"));
}

int run_classifier(const ClassifierOptions& o) {
  // Default: the auto profile; simulated HDL-64E scans measure as kitti-hdl64, so only a real
  // folder is measured.
  const io::PipelineConfig config =
      !o.config_path.empty() ? io::read_pipeline_config(o.config_path)
      : o.real_dir.empty()   ? io::pipeline_preset("kitti-hdl64")
                             : io::auto_pipeline_config(io::measure_sequence(io::Sequence::open(o.real_dir)));
  TrainingPairConfig pc;
  pc.k = config.localizer.retrieval.k;
  pc.seed = o.seed;
  pc.negatives_per_positive = 1000000;  // evaluate on every candidate, not a 1:50 sample
  std::unique_ptr<sim::LabelledCity> city;
  std::unique_ptr<eval::RealPairs> real;
  std::string title;
  if (o.real_dir.empty()) {
    sim::SegmentsAlongConfig along;
    along.local_cloud = config.local_cloud;
    along.segmentation = config.localizer.segmentation;
    along.segment_map = config.segment_map;
    std::fprintf(stderr, "simulating held-out city %llu (%s)...\n", static_cast<unsigned long long>(o.seed),
                 o.preset.c_str());
    city = sim::labelled_city(sim::dataset_preset(o.preset, o.seed), sim::lidar_model_by_name(o.sensor), along, pc);
    title = "ROC on held-out city " + std::to_string(o.seed);
  } else {
    eval::RealPairsConfig rc;  // the stretches segmatch-train --real holds out
    rc.pairs = pc;
    real = eval::real_pairs(o.real_dir, config, rc);
    title = "ROC on held-out stretches of " + fs::path(o.real_dir).filename().string();
  }
  const TrainingPairs& p = city ? city->pairs : real->held_out;
  const Segments& targets = city ? city->targets : real->targets_held_out;
  const FeatureScaling scaling = FeatureScaling::fit(targets);
  std::vector<std::pair<std::string, std::function<double(const Segment&, const Segment&)>>> scorers = {
      {"L2", [&](const Segment& q, const Segment& t) { return -scaling.distance(q.eigen, t.eigen); }}};
  std::vector<std::unique_ptr<RandomForestMatcher>> models;
  for (const auto& [name, path] :
       {std::pair<std::string, std::string>{"RF_eigen", o.model_eigen}, {"RF_eigen+shapes", o.model_shapes}}) {
    if (path.empty()) continue;
    models.push_back(std::make_unique<RandomForestMatcher>(load_model(path)));
    const RandomForestMatcher* rf = models.back().get();
    scorers.push_back({name, [rf](const Segment& q, const Segment& t) { return rf->probability(q, t); }});
  }
  std::vector<eval::RocCurve> curves;
  nlohmann::json j;
  j["pairs"] = {{"positives", p.positives}, {"negatives", p.negatives}};
  if (real)
    j["pairs"]["real"] = o.real_dir;
  else
    j["pairs"]["city_seed"] = o.seed, j["pairs"]["preset"] = o.preset;
  for (const auto& [name, scorer] : scorers) {
    std::vector<eval::ScoredPair> scored;
    for (size_t i = 0; i < p.pairs.size(); ++i)
      scored.push_back({scorer(*p.pairs[i].first, *p.pairs[i].second), p.same_object[i]});
    curves.push_back(eval::roc_curve(name, std::move(scored), 0.2));
    const eval::RocCurve& c = curves.back();
    std::printf("%-16s AUC %.3f; at FPR <= 0.2: TPR %.3f (FPR %.3f, threshold %.3f)\n", name.c_str(), c.auc,
                c.operating_tpr, c.operating_fpr, c.operating_threshold);
    j["curves"][name] = {{"auc", c.auc},
                         {"operating_tpr", c.operating_tpr},
                         {"operating_fpr", c.operating_fpr},
                         {"operating_threshold", c.operating_threshold}};
  }
  std::printf("held-out pairs: %zu positives, %zu negatives\n", p.positives, p.negatives);
  if (!o.out_dir.empty()) {
    fs::create_directories(o.out_dir);
    eval::plot_roc((fs::path(o.out_dir) / "roc.png").string(), curves, title);
    std::ofstream(fs::path(o.out_dir) / "roc.json") << j.dump(2) << "\n";
    std::printf("report: %s/{roc.png, roc.json}\n", o.out_dir.c_str());
  }
  return 0;
}

SegmenterType segmenter_of(const std::string& name) {
  if (name == "region_growing") return SegmenterType::kRegionGrowing;
  return name == "range_image" ? SegmenterType::kRangeImage : SegmenterType::kEuclidean;
}

// Every option of the three subcommands, filled by the command line.
struct EvalArgs {
  eval::LocalizationRunConfig lc, fc;  // localize, funnel
  ClassifierOptions co;
  std::string server, token_file, out_dir;
  std::string cloud_poses = "odometry", funnel_cloud_poses = "odometry";
  float recent_window_m = -1.0f;
  std::string search = "map", segmenter = "map", track_surfaces = "on";
  bool segments = false;
};

CLI::IsMember segmenter_names() { return CLI::IsMember({"map", "euclidean", "region_growing", "range_image"}); }

CLI::App* add_localize(CLI::App& app, EvalArgs& a) {
  CLI::App* loc = app.add_subcommand("localize", "replay a traversal against a map and score every answer");
  loc->add_option("--map", a.lc.map_path, "map database")->required();
  loc->add_option("--query", a.lc.query_folder, "sequence to replay; its poses are the ground truth in the map frame");
  loc->add_option("--sim", a.lc.sim_dataset, "segmatch-sim folder: replay sequences/01 with its exact ground truth");
  cli::add_bag_options(*loc, a.lc.bag.points_topic, a.lc.bag.pose_topic, a.lc.bag.map_frame, a.lc.bag.sensor_frame);
  loc->add_option("--server", a.server, "HOST:PORT of segmatch-server (default: localize in-process)");
  loc->add_option("--token-file", a.token_file, "file holding the server's shared secret");
  loc->add_option("--every-m", a.lc.replay.every_m, "one query every this many metres");
  loc->add_option("--warmup-m", a.lc.replay.warmup_m, "no query before this much driving (default 30)");
  loc->add_option("--first", a.lc.replay.first, "first scan");
  loc->add_option("--last", a.lc.replay.last, "last scan");
  loc->add_option("--stride", a.lc.replay.stride, "use every n-th scan");
  loc->add_flag(
      "--single-scan", a.lc.replay.single_scan,
      "cold start: every query is one raw scan alone, as a vehicle that has just woken up has (no accumulation, "
      "no warm-up; its newest scans are that scan)");
  loc->add_option("--mapped-radius-m", a.lc.thresholds.mapped_radius_m,
                  "a street is mapped within this of the map trajectory");
  loc->add_flag("!--quiet", a.lc.print_each, "no line per query");
  loc->add_flag(
      "--track", a.lc.track,
      "track between fixes (api::Tracker): each query's prior is the last fix, its radius grows with the distance "
      "driven since");
  loc->add_option(
      "--odometry", a.lc.odometry_path,
      "the vehicle's odometry poses (KITTI or TUM) that build every query's local cloud (default: the replayed "
      "sequence's odom_poses.txt)");
  loc->add_option("--reference", a.lc.reference_path,
                  "score against this poses file of the query sequence (KITTI or TUM) instead of its poses.txt");
  loc->add_option("--cloud-poses", a.cloud_poses,
                  "odometry (default): local clouds from the vehicle's odometry, as on a car; reference: from the "
                  "sequence's reference poses, a comparison that flatters every figure (the report says so)")
      ->check(CLI::IsMember({"odometry", "reference"}));
  loc->add_option("--gnss-sigma-m", a.lc.gnss_sigma_m,
                  "GNSS-like priors: the true pose plus Gaussian noise of this many metres (seeded), radius 3 sigma");
  loc->add_option("--gnss-seed", a.lc.gnss_seed, "seed of the GNSS noise (default 1)");
  loc->add_option("--wrong-prior-m", a.lc.wrong_prior_m,
                  "a stress test: every query's prior is the true pose moved this many metres in a seeded random "
                  "horizontal direction (--gnss-seed), with radius --wrong-prior-radius-m; any fix it gives is false");
  loc->add_option("--wrong-prior-radius-m", a.lc.wrong_prior_radius_m,
                  "the radius the wrong priors claim (default 3 m)");
  loc->add_flag("--compare-global", a.lc.compare_global,
                "also send every query that has a prior without it (not scored) and report both server times");
  cli::add_output_option(*loc, a.out_dir, "report folder (JSON + PNG)");
  loc->add_option(
      "--recent-window-m", a.recent_window_m,
      "in-process only: localize with this refine.recent_window_m instead of the map's (0: the whole cloud's "
      "pose); a what-if on a stored map");
  loc->add_option("--max-scan-age-m", a.lc.max_scan_age_m,
                  "the vehicle's local cloud holds each scan for this many metres of driving instead of the map's "
                  "local_cloud.max_scan_age_m (0: until it leaves the cylinder); a what-if");
  loc->add_option("--newest-m", a.lc.replay.newest_m,
                  "each query also carries the scans of the last this many metres, to which the server refines its "
                  "answer (the sensor's pose now; default 10, 0: none)");
  loc->add_option(
         "--search", a.search,
         "in-process only: the wide-prior search (search.enabled) on or off instead of as the map says; a what-if")
      ->check(CLI::IsMember({"map", "on", "off"}));
  loc->add_option("--segmenter", a.segmenter,
                  "in-process only: segment the queries with this segmenter instead of the map's (the map's segments "
                  "stay); a what-if, e.g. range_image for --single-scan")
      ->check(segmenter_names());
  loc->add_flag(
      "--segments", a.segments,
      "query by segments (LOCALIZE_SEGMENTS): segment and describe each local cloud here, as a vehicle would, "
      "and send the segments instead of the cloud");
  loc->add_option(
         "--track-surfaces", a.track_surfaces,
         "with a narrow prior and newest scans, track on the surface layer first (protocol revision 11): the cloud "
         "path sets LOCALIZE bit 6; --segments sends the tracking request (nearby segments without points, the newest "
         "scans thinned) and the full one only after TRACKING_LOST (default on)")
      ->check(CLI::IsMember({"on", "off"}));
  return loc;
}

CLI::App* add_funnel(CLI::App& app, EvalArgs& a) {
  CLI::App* fun =
      app.add_subcommand("funnel", "where true matches are lost: segments, counterparts, retrieved, classified");
  fun->add_option("--map", a.fc.map_path, "map database")->required();
  fun->add_option("--query", a.fc.query_folder, "sequence to replay; its poses are the ground truth in the map frame");
  fun->add_option("--sim", a.fc.sim_dataset, "segmatch-sim folder: sequences/01 with its exact ground truth");
  fun->add_option("--every-m", a.fc.replay.every_m, "one query every this many metres");
  fun->add_option("--warmup-m", a.fc.replay.warmup_m, "no query before this much driving (default 30)");
  fun->add_option("--first", a.fc.replay.first, "first scan");
  fun->add_option("--last", a.fc.replay.last, "last scan");
  fun->add_option("--stride", a.fc.replay.stride, "use every n-th scan");
  fun->add_flag("--single-scan", a.fc.replay.single_scan, "every query one raw scan alone, as for localize");
  fun->add_option("--segmenter", a.segmenter,
                  "segment the queries with this segmenter instead of the map's, as for localize")
      ->check(segmenter_names());
  fun->add_option("--odometry", a.fc.odometry_path, "the vehicle's odometry poses (default: QUERY/odom_poses.txt)");
  fun->add_option("--cloud-poses", a.funnel_cloud_poses, "odometry (default) or reference, as for localize")
      ->check(CLI::IsMember({"odometry", "reference"}));
  return fun;
}

CLI::App* add_classifier(CLI::App& app, EvalArgs& a) {
  CLI::App* cls = app.add_subcommand(
      "classifier", "ROC curves of the match classifiers on a held-out simulated city or real stretches");
  cls->add_option("--model", a.co.model_shapes, "RF_eigen+shapes model file");
  cls->add_option("--model-eigen", a.co.model_eigen, "RF_eigen model file");
  cls->add_option("--preset", a.co.preset, "city size: tiny, demo, city");
  cls->add_option("--seed", a.co.seed, "held-out city seed (not one the models were trained on)");
  cls->add_option("--config", a.co.config_path, "pipeline config JSON");
  cls->add_option("--real", a.co.real_dir,
                  "real keyframe folder instead of a city: every candidate pair of the stretches segmatch-train --real "
                  "holds out, labelled by centroid distance (default config: the auto profile measured from it)");
  cli::add_output_option(*cls, a.co.out_dir, "report folder");
  return cls;
}

// The in-process what-ifs (--recent-window-m, --search, --segmenter) change the map as loaded;
// a server serves its own.
int localize_command(EvalArgs& a) {
  eval::LocalizationRunConfig& lc = a.lc;
  if (lc.query_folder.empty() == lc.sim_dataset.empty())
    throw std::runtime_error("give exactly one of --query and --sim");
  lc.cloud_poses = io::parse_cloud_poses(a.cloud_poses);
  server::MapLoadOptions load;
  if (a.recent_window_m >= 0.0f) {
    if (!a.server.empty())
      throw std::runtime_error("--recent-window-m is for in-process runs (the server serves its map's)");
    load.recent_window_m = a.recent_window_m;
  }
  if (a.search != "map") {
    if (!a.server.empty()) throw std::runtime_error("--search is for in-process runs (the server serves its map's)");
    load.search_enabled = a.search == "on";
  }
  if (a.segmenter != "map") {
    if (!a.server.empty()) throw std::runtime_error("--segmenter is for in-process runs (the server serves its map's)");
    load.segmenter = segmenter_of(a.segmenter);
  }
  lc.track_surfaces = a.track_surfaces == "on";
  return run_localize(lc, a.server, a.token_file, a.out_dir, a.segments, lc.track_surfaces, load);
}

int funnel_command(EvalArgs& a) {
  eval::LocalizationRunConfig& fc = a.fc;
  if (fc.query_folder.empty() == fc.sim_dataset.empty())
    throw std::runtime_error("give exactly one of --query and --sim");
  server::MapLoadOptions funnel_load;
  if (a.segmenter != "map") funnel_load.segmenter = segmenter_of(a.segmenter);
  const auto loaded = server::load_map(fc.map_path, funnel_load);
  fc.replay.local_cloud = loaded->config.local_cloud;
  fc.cloud_poses = io::parse_cloud_poses(a.funnel_cloud_poses);
  fc.replay.voxel = loaded->config.localizer.segmentation.voxel;
  eval::print_funnel(eval::run_funnel(fc, *loaded->localizer), loaded->config.localizer.verification.min_inliers);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Evaluate SegMatch localization and classifiers against ground truth"};
  app.require_subcommand(1);
  EvalArgs a;
  const CLI::App* loc = add_localize(app, a);
  const CLI::App* fun = add_funnel(app, a);
  add_classifier(app, a);
  cli::add_version_flag(app, "segmatch-eval");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (const int status = cli::check_server("segmatch-eval", a.server); status >= 0) return status;
  try {
    if (*loc) return localize_command(a);
    if (*fun) return funnel_command(a);
    return run_classifier(a.co);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-eval: %s\n", e.what());
    return 1;
  }
}
