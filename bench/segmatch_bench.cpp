// segmatch-bench: the time of ONE localization query, module by module (median and p90), on a
// simulated HDL-64E local cloud (60 m radius) against a map of a few km, and on real local
// clouds accumulated from the riverside02 keyframes (OS1-64). The stock PCL stages the
// original SegMatch ran (VoxelGrid, EuclideanClusterExtraction, ESFEstimation) are timed on
// the same clouds. Target (issue): whole query <= 100 ms median on one core; the paper
// (Dube et al., ICRA 2017) needed 0.8-1.2 s per query. Queries run one after the other on the
// calling thread; the CPU column shows whether a query used more than one core.
#include "pcl_stages.h"
#include "query_log.h"
#include "query_plan.h"
#include "segmatch/cli/progress.h"
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/preprocess/voxel_accumulator.h"
#include "segmatch/core/training/training.h"
#include "segmatch/io/sequence.h"
#include "segmatch/sim/city.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/keyframes.h"
#include "segmatch/sim/local_clouds.h"

#include <CLI/CLI.hpp>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

using namespace segmatch;
using Clock = std::chrono::steady_clock;
using bench::kQueryWarmupM;
using bench::median;
using bench::ms_since;
using bench::quantile;
using bench::QueryLog;
using bench::spread;

namespace {

constexpr double kTargetMs = 100.0;
struct Options {
  std::string preset = "demo";
  uint64_t seed = 1;
  int queries = 15;
  double map_every_m = 5.0;
  double map_km = 0.0;  // 0: the preset's first traversal
  std::string real_dir;
  bool real_dir_given = false, skip_real = false, skip_pcl = false;
  int threads = 0;
  int pcl_clouds = 5;
  int repeat = 1;  // voxelized queries: localizations per query cloud (profiling, steadier medians)
};

double cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

// Up to --queries of `eligible` frames spread evenly, and --pcl-clouds of those for PCL.
void pick_queries(const std::vector<size_t>& eligible, const Options& o, std::set<size_t>* selected,
                  std::set<size_t>* compared) {
  const std::vector<size_t> picks = spread(eligible.size(), static_cast<size_t>(o.queries));
  for (size_t i : picks) selected->insert(eligible[i]);
  for (size_t i : spread(picks.size(), o.skip_pcl ? 0 : static_cast<size_t>(o.pcl_clouds)))
    compared->insert(eligible[picks[i]]);
}

PointCloud transformed(PointCloud cloud, const Pose3d& T) {
  const Eigen::Isometry3f Tf = T.cast<float>();
  for (Point& p : cloud) {
    const Eigen::Vector3f q = Tf * p.xyz();
    p.x = q.x(), p.y = q.y(), p.z = q.z();
  }
  return cloud;
}

// ---------------------------------------------------------------------------------------------
// Simulated city.

// World-frame segments of local clouds every `every_m` along `t` (merged as a map, or all).
Segments segments_along(const sim::World& world, const sim::Traversal& t, double every_m,
                        const SegmentationConfig& config, uint64_t seed, bool merge, bool labels, int threads,
                        const std::string& what) {
  const sim::RayCaster caster(world.scene());
  SegmentMap map;
  Segments all;
  sim::LocalCloudSchedule schedule;
  schedule.every_m = every_m;
  schedule.seed = seed;
  schedule.threads = threads;
  cli::Progress bar(what, t.size(), "scans");
  sim::for_each_local_cloud(caster, sim::hdl64e(), t, without_age_limit(LocalCloudConfig{}), schedule,
                            [&](const sim::SimulatedLocalCloud& lc) {
                              Segments s = extract_segments(lc.cloud, lc.T_world_sensor.translation().cast<float>(),
                                                            config, labels ? &lc.labels : nullptr);
                              if (merge)
                                map.add(std::move(s));
                              else
                                std::move(s.begin(), s.end(), std::back_inserter(all));
                              bar.update(lc.frame + 1);
                            });
  bar.update(t.size());
  bar.finish();
  return merge ? map.segments() : all;
}

// Trained as the end-to-end test does, on another (tiny) city than the one queried.
std::shared_ptr<RandomForestMatcher> train_classifier(uint64_t seed, const LocalizerConfig& config, int threads) {
  const auto start = Clock::now();
  const sim::City city = sim::make_city(sim::dataset_preset("tiny", seed));
  const Segments targets =
      segments_along(city.world, city.first, 5.0, config.segmentation, 11, true, true, threads, "training map");
  const Segments queries = segments_along(city.changed, city.second, 10.0, config.segmentation, 12, false, true,
                                          threads, "training queries");
  FeatureIndex index;
  index.build(targets);
  const TrainingPairs p = label_pairs_by_instance(queries, targets, index, TrainingPairConfig{});
  auto rf = std::make_shared<RandomForestMatcher>(config.matcher);
  rf->train(p.pairs, p.same_object);
  std::printf("classifier: random forest trained on tiny city seed %llu: %zu positives, %zu negatives (%.1f s)\n",
              static_cast<unsigned long long>(seed), p.positives, p.negatives, ms_since(start) / 1000.0);
  return rf;
}

// The preset, its first traversal cut to --map-km. Throws std::invalid_argument.
sim::DatasetConfig sim_config(const Options& o) {
  sim::DatasetConfig c = sim::dataset_preset(o.preset, o.seed);
  if (o.map_km > 0) c.first_length_m = o.map_km * 1000.0;
  c.threads = o.threads;
  c.validate();
  return c;
}

double run_sim(const Options& o, double* voxelized_ms) {
  const sim::DatasetConfig c = sim_config(o);
  const LocalizerConfig config;  // the paper's parameters (KITTI HDL-64E)
  std::printf("== simulated: preset %s, seed %llu, HDL-64E, local cloud radius %.0f m\n", o.preset.c_str(),
              static_cast<unsigned long long>(o.seed), LocalCloudConfig{}.radius_m);
  auto start = Clock::now();
  const sim::City city = sim::make_city(c);
  std::printf("world: %.1f km of streets, %zu objects; first traversal %.2f km (map), second %.2f km (queries)\n",
              city.world.streets.total_length_m() / 1000.0, city.world.objects.size(), city.first.length_m() / 1000.0,
              city.second.length_m() / 1000.0);
  const auto classifier = train_classifier(o.seed + 100, config, o.threads);

  start = Clock::now();
  Segments map = segments_along(city.world, city.first, o.map_every_m, config.segmentation, mix_seed(o.seed, 21), true,
                                false, o.threads, "map");
  std::printf("map: %zu segments from local clouds every %.1f m along %.2f km (%.1f s)\n", map.size(), o.map_every_m,
              city.first.length_m() / 1000.0, ms_since(start) / 1000.0);
  const Localizer localizer(config, std::move(map), classifier);

  // Queries: local clouds of the revisit (changed world, other lane) on mapped streets.
  const bench::QueryPlan plan = bench::plan_queries(city, o.queries, o.skip_pcl ? 0 : o.pcl_clouds, o.seed, o.threads);
  const std::set<size_t>& selected = plan.selected;
  const std::set<size_t>& compared = plan.compared;

  QueryLog log, voxel_log;
  std::vector<double> upkeep_ms;  // per kept scan: VoxelAccumulator::add_scan + evict
  bench::StageComparison comparison;
  // The vehicle's odometry, as a LiDAR-inertial one drifts (sim::KeyframeConfig's defaults): the
  // local clouds are built with it, the answers scored against the truth.
  Poses truth_query;
  for (const Pose3d& T : city.second.T_world_lidar)
    truth_query.push_back(city.second.T_world_lidar.front().inverse() * T);
  sim::KeyframeConfig drift;
  drift.odom_seed = o.seed;
  const Poses odometry = sim::drifted_odometry(truth_query, drift);
  const sim::RayCaster caster(city.changed.scene());
  // The vehicle's two ways of keeping its local cloud, fed the same scans in its odometry frame:
  // the raw scans (LocalCloud, cropped and voxelized by the query) and the incremental voxel
  // grid (VoxelAccumulator, evicting after every scan, cropped voxels sent with protocol flag
  // bit 1, CloudKind::kVoxelized).
  LocalCloud raw(LocalCloudConfig{});
  VoxelAccumulator voxels(LocalCloudConfig{}, config.segmentation.voxel);
  cli::Progress bar("queries", city.second.size(), "scans");
  sim::for_each_kept_scan(
      caster, sim::hdl64e(), city.second, LocalCloudConfig{}, plan.schedule,
      [&](size_t frame, const sim::SimulatedScan& scan) {
        bar.update(frame + 1);
        const Pose3d T_world_sensor = city.second.T_world_lidar[frame];
        const Pose3d& T_query_sensor = odometry[frame];
        raw.add_scan(scan.points, T_query_sensor);
        const auto t0 = Clock::now();
        voxels.add_scan(scan.points, T_query_sensor);
        voxels.evict(T_query_sensor);
        upkeep_ms.push_back(ms_since(t0));
        if (!selected.count(frame)) return;
        const Eigen::Vector3f sensor = T_query_sensor.translation().cast<float>();
        const PointCloud cloud = raw.crop(T_query_sensor);
        const double cpu0 = cpu_ms();
        const LocalizationResult r = localizer.localize(cloud, sensor);
        log.add(r, cpu_ms() - cpu0, cloud.size(), T_query_sensor, T_world_sensor);
        const double cpu1 = cpu_ms();
        const auto t1 = Clock::now();
        const PointCloud cropped = voxels.crop(T_query_sensor);
        const double crop_ms = ms_since(t1), crop_cpu_ms = cpu_ms() - cpu1;
        for (int rep = 0; rep < o.repeat; ++rep) {
          const double cpu2 = cpu_ms();
          LocalizationResult rv = localizer.localize(cropped, sensor, CloudKind::kVoxelized);
          rv.timings.voxel_ms = crop_ms;  // the incremental grid's crop stands in for the voxel grid
          rv.timings.total_ms += crop_ms;
          voxel_log.add(rv, cpu_ms() - cpu2 + crop_cpu_ms, cropped.size(), T_query_sensor, T_world_sensor);
        }
        if (compared.count(frame)) comparison.run(cloud, sensor, config.segmentation);
      });
  bar.update(city.second.size());
  bar.finish();
  if (log.timings.size() != selected.size())
    std::printf("warning: %zu of %zu selected local clouds were produced (schedule mismatch)\n", log.timings.size(),
                selected.size());
  log.print(
      "simulated (random forest matcher, classifier trained in-process), raw local cloud from drifting "
      "simulated odometry");
  voxel_log.print(
      "simulated, the same queries from the vehicle's incremental voxel grid (VoxelAccumulator; "
      "voxel = its crop; the server path of protocol flag bit 1)");
  std::printf(
      "  voxel grid upkeep per kept scan (add_scan + evict, every 1 m driven, between queries): "
      "median %.1f ms, p90 %.1f ms\n",
      median(upkeep_ms), quantile(upkeep_ms, 0.9));
  if (!o.skip_pcl) comparison.print("simulated", config.segmentation);
  if (voxelized_ms) *voxelized_ms = voxel_log.timings.empty() ? NAN : voxel_log.total_median();
  return log.timings.empty() ? NAN : log.total_median();
}

// ---------------------------------------------------------------------------------------------
// Real keyframes (PCD, sensor frame, poses T_world_sensor).

double run_real(const Options& o, const io::Sequence& seq) {
  const std::string& dir = seq.folder();
  const Poses& poses = seq.poses();
  // The queries' local clouds come from the vehicle's odometry when the recording has one.
  const std::filesystem::path odom_path = std::filesystem::path(dir) / "odom_poses.txt";
  const bool has_odometry = std::filesystem::is_regular_file(odom_path);
  const Poses odometry = has_odometry ? io::Sequence::open(dir, {odom_path.string()}).poses() : poses;
  if (seq.size() < 8) throw std::runtime_error(dir + ": too few keyframes (" + std::to_string(seq.size()) + ")");
  // Parameters for these pre-downsampled keyframes (../shared/data/README.md).
  LocalizerConfig config;
  config.segmentation.voxel.leaf_m = 0.2f;
  config.segmentation.voxel.min_points_per_voxel = 1;
  config.segmentation.segmenter.cluster_distance_m = 0.4f;
  config.segmentation.segmenter.min_points = 30;
  config.matcher.type = MatcherType::kL2;  // no labels to train a classifier on
  config.validate();
  const LocalCloudConfig lc_config;
  std::printf("\n== real: %s, %zu keyframes; map from even keyframes, queries from odd ones\n", dir.c_str(),
              seq.size());
  std::printf(
      "parameters: voxel %.1f m (>= %d point), cluster distance %.1f m, >= %d points, L2 matcher on "
      "eigen features (ESF still computed), local cloud radius %.0f m\n",
      config.segmentation.voxel.leaf_m, config.segmentation.voxel.min_points_per_voxel,
      config.segmentation.segmenter.cluster_distance_m, config.segmentation.segmenter.min_points, lc_config.radius_m);

  auto start = Clock::now();
  LocalCloud map_cloud(without_age_limit(lc_config));  // a map's clouds hold every scan (MapBuilder)
  SegmentMap map;
  double map_m = 0;
  {
    cli::Progress bar("real map", (seq.size() + 1) / 2, "keyframes");
    for (size_t i = 0; i < seq.size(); i += 2) {
      if (i >= 2) map_m += (poses[i].translation() - poses[i - 2].translation()).norm();
      map_cloud.add_scan(seq.scan(i).points, poses[i]);
      const PointCloud cloud = map_cloud.crop(poses[i]);
      map.add(extract_segments(cloud, poses[i].translation().cast<float>(), config.segmentation));
      bar.update(i / 2 + 1);
    }
  }
  std::printf("map: %zu segments from %zu local clouds along %.2f km (%.1f s)\n", map.size(), (seq.size() + 1) / 2,
              map_m / 1000.0, ms_since(start) / 1000.0);
  const Localizer localizer(config, map.segments());

  std::vector<size_t> eligible;
  double driven = 0;
  for (size_t k = 3; k < seq.size(); k += 2) {
    driven += (poses[k].translation() - poses[k - 2].translation()).norm();
    if (driven >= kQueryWarmupM) eligible.push_back(k);
  }
  std::set<size_t> selected, compared;
  pick_queries(eligible, o, &selected, &compared);
  std::printf("queries: %zu local clouds of odd keyframes after >= %.0f m of driving, in the frame of keyframe 1\n",
              selected.size(), kQueryWarmupM);

  QueryLog log;
  bench::StageComparison comparison;
  LocalCloud query_cloud(lc_config);
  const Pose3d T_query_world = odometry[1].inverse();
  const size_t last = selected.empty() ? 0 : *selected.rbegin();
  cli::Progress bar("real queries", last / 2 + 1, "keyframes");
  for (size_t k = 1; k <= last; k += 2) {
    query_cloud.add_scan(seq.scan(k).points, odometry[k]);
    bar.update(k / 2 + 1);
    if (!selected.count(k)) continue;
    const PointCloud cloud = transformed(query_cloud.crop(odometry[k]), T_query_world);
    const Pose3d T_query_sensor = T_query_world * odometry[k];
    const Eigen::Vector3f sensor = T_query_sensor.translation().cast<float>();
    const double cpu0 = cpu_ms();
    const LocalizationResult r = localizer.localize(cloud, sensor);
    log.add(r, cpu_ms() - cpu0, cloud.size(), T_query_sensor, poses[k]);
    if (compared.count(k)) comparison.run(cloud, sensor, config.segmentation);
  }
  bar.update(last / 2 + 1);
  bar.finish();
  log.print(has_odometry
                ? "real riverside02 (L2 matcher; local clouds from odom_poses.txt, reference = poses.txt)"
                : "real riverside02 (L2 matcher; no odom_poses.txt: local clouds from the reference poses.txt)");
  if (!o.skip_pcl) comparison.print("real riverside02", config.segmentation);
  return log.timings.empty() ? NAN : log.total_median();
}

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown CPU";
}

void verdict(const char* what, double ms) {
  if (std::isnan(ms)) return;
  std::printf("whole query, %s: median %.1f ms vs target %.0f ms on one core: %s\n", what, ms, kTargetMs,
              ms <= kTargetMs ? "met" : "NOT met");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Per-module timing of one SegMatch localization query (simulated and real), vs stock PCL stages"};
  Options o;
  app.add_option("--preset", o.preset, "simulated world; its first traversal builds the map (tiny, demo, city)");
  app.add_option("--seed", o.seed, "world seed (the classifier's tiny city uses seed + 100)");
  app.add_option("--queries", o.queries, "queries per data set")->check(CLI::Range(1, 100000));
  app.add_option("--map-every-m", o.map_every_m, "map: one local cloud every this many metres")
      ->check(CLI::Range(0.5, 1000.0));
  app.add_option("--map-km", o.map_km, "cut the first traversal (the map) to this length, e.g. city with 3")
      ->check(CLI::Range(0.05, 200.0));
  auto* real_opt = app.add_option("--real-dir", o.real_dir, "real PCD keyframe folder (default: shared riverside02)");
  app.add_flag("--skip-real", o.skip_real, "skip the real data set");
  app.add_flag("--skip-pcl", o.skip_pcl, "skip the PCL comparison");
  app.add_option("--repeat", o.repeat, "localize each voxelized simulated query this many times (profiling)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--pcl-clouds", o.pcl_clouds, "query clouds per data set timed with PCL")->check(CLI::Range(1, 1000));
  app.add_option("--threads", o.threads, "scan simulation threads (0: one per core); queries always run on one")
      ->check(CLI::Range(0, 256));
  CLI11_PARSE(app, argc, argv);
  o.real_dir_given = real_opt->count() > 0;
  if (!o.real_dir_given) o.real_dir = std::string(SEGMATCH_SHARED_DATA_DIR) + "/real/riverside02";

  try {
    if (o.real_dir_given && !o.skip_real && !std::filesystem::is_directory(o.real_dir)) {
      std::fprintf(stderr, "segmatch-bench: error: --real-dir %s: no such folder\n", o.real_dir.c_str());
      return 2;
    }
    sim_config(o);  // bad options fail before any output
    // Open the real sequence first: a broken folder fails before minutes of simulation.
    std::optional<io::Sequence> real;
    if (!o.skip_real && std::filesystem::is_directory(o.real_dir)) real = io::Sequence::open(o.real_dir);
    std::printf(
        "segmatch-bench on %s, %u hardware threads; target: whole query <= %.0f ms median on one core "
        "(paper: 0.8-1.2 s per query)\n",
        cpu_model().c_str(), std::thread::hardware_concurrency(), kTargetMs);
    double sim_voxelized_ms = NAN;
    const double sim_ms = run_sim(o, &sim_voxelized_ms);
    double real_ms = NAN;
    if (o.skip_real)
      std::printf("\n== real: skipped (--skip-real)\n");
    else if (!real)
      std::printf("\n== real: skipped, %s not found (the shared data is not part of a fresh clone)\n",
                  o.real_dir.c_str());
    else
      real_ms = run_real(o, *real);
    std::printf("\n");
    verdict("simulated HDL-64E, raw local cloud", sim_ms);
    verdict("simulated HDL-64E, from the incremental voxel grid (crop + localize)", sim_voxelized_ms);
    verdict("real riverside02", real_ms);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-bench: error: %s\n", e.what());
    return 1;
  }
}
