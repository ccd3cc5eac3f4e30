#include "segmatch/eval/localization_run.h"

#include <segmatch/api/tracker.h>

#include "query_priors.h"

#include "segmatch/cli/progress.h"
#include "segmatch/eval/plots.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/storage/map_reader.h"

#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>

namespace segmatch {
namespace eval {
namespace {

namespace fs = std::filesystem;

double distance_to(const std::vector<Eigen::Vector3d>& path, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& q : path) best = std::min(best, (q - p).head<2>().norm());
  return best;
}

api::LocalizeRequest request_of(const io::ReplayQuery& q) {
  api::LocalizeRequest r;
  r.request_id = q.frame;
  r.flags |= api::kFlagDetail;  // the window's warp, for the report
  if (q.voxelized) r.flags |= api::kFlagVoxelized;
  r.sensor_position_local = q.T_odom_sensor.translation();
  r.sensor_orientation_local = Eigen::Quaterniond(q.T_odom_sensor.linear()).normalized();
  r.points = q.cloud_odom;
  if (!q.newest_odom.empty()) {
    r.flags |= api::kFlagNewestScans;
    r.newest_points = q.newest_odom;
  }
  return r;
}

void add_timings(std::map<std::string, std::vector<double>>& t, const api::ModuleTimingsMs& m) {
  const std::pair<const char*, float> all[] = {{"voxel", m.voxel},       {"ground", m.ground},
                                               {"segment", m.segment},   {"describe", m.describe},
                                               {"retrieve", m.retrieve}, {"classify", m.classify},
                                               {"verify", m.verify},     {"refine", m.refine},
                                               {"total", m.total},       {"server_total", m.server_total}};
  for (const auto& [name, ms] : all) t[name].push_back(ms);
}

}  // namespace

Truth open_truth(const LocalizationRunConfig& c) {
  if (c.sim_dataset.empty()) {
    io::SequenceOptions so;
    so.poses_path = c.reference_path;
    so.bag = c.bag;
    if (!c.reference_path.empty()) so.bag.pose_topic = so.bag.map_frame = so.bag.sensor_frame = "";
    io::Sequence seq = io::Sequence::open(c.query_folder, so);
    Poses truth = seq.poses();
    return {std::move(seq), std::move(truth)};
  }
  const fs::path dir(c.sim_dataset);
  io::Sequence seq = io::Sequence::open((dir / "sequences" / "01").string());
  const Poses world_00 = io::read_kitti_poses((dir / "ground_truth" / "lidar_poses_00.txt").string());
  const Poses world_01 = io::read_kitti_poses((dir / "ground_truth" / "lidar_poses_01.txt").string());
  if (world_00.empty() || world_01.size() != seq.size())
    throw std::runtime_error(c.sim_dataset + ": ground truth poses do not match sequences/01 (" +
                             std::to_string(world_01.size()) + " poses, " + std::to_string(seq.size()) + " scans)");
  const Pose3d T_map_world = world_00.front().inverse();
  Poses truth;
  for (const Pose3d& T_world_sensor : world_01) truth.push_back(T_map_world * T_world_sensor);
  return {std::move(seq), std::move(truth)};
}

namespace {

// Where the vehicle's local clouds come from (LocalizationRunConfig::cloud_poses): the replayed
// sequence with its scans placed by the vehicle's odometry (returned), or by the reference
// (nothing returned: the truth's own sequence is replayed). Names the poses file in `run`.
std::optional<io::Sequence> open_cloud_poses(const LocalizationRunConfig& c, const Truth& truth, LocalizationRun& run) {
  run.cloud_poses = c.cloud_poses;
  const bool bag = truth.sequence.layout() == io::SequenceLayout::kBag;
  if (bag && c.cloud_poses == io::CloudPoses::kOdometry && c.odometry_path.empty()) {
    run.cloud_poses_file = truth.sequence.source_note();  // the bag's poses are the vehicle's
    return std::nullopt;
  }
  if (c.cloud_poses == io::CloudPoses::kOdometry) {
    io::SequenceOptions so;
    if (bag) {
      so.poses_path = c.odometry_path;
      so.bag.points_topic = c.bag.points_topic;
    } else {
      so.poses_path = io::odometry_poses_path(truth.sequence.folder(), c.odometry_path);
    }
    run.cloud_poses_file = so.poses_path;
    return io::Sequence::open(truth.sequence.folder(), so);
  }
  if (!c.odometry_path.empty()) throw std::runtime_error("--odometry and --cloud-poses reference exclude each other");
  run.cloud_poses_file =
      c.reference_path.empty() ? (fs::path(truth.sequence.folder()) / "poses.txt").string() : c.reference_path;
  return std::nullopt;
}

// One query's answer scored against the truth (thresholds, the mapped streets of the map's trajectory).
QueryOutcome outcome_of(const io::ReplayQuery& q, const api::LocalizeReply& reply, const std::string& mode,
                        bool rejected, double latency_ms, const Truth& truth, const LocalizationRun& run,
                        const LocalizationRunConfig& c) {
  QueryOutcome o;
  o.latency_ms = latency_ms;
  o.frame = q.frame;
  o.odometer_m = q.odometer_m;
  o.localized = reply.status == api::LocalizeStatus::kLocalized;
  o.status = api::to_string(reply.status);
  o.mode = mode;
  o.rejected = rejected;
  o.server_ms = reply.timings.server_total;
  o.inliers = reply.inliers;
  o.support = reply.support;
  o.confidence = reply.confidence;
  if (reply.detail)
    o.window_warp_m = reply.detail->window_warp_m, o.window_warp_deg = reply.detail->window_warp_deg,
    o.window_points = reply.detail->window_points;
  const Pose3d& T_map_sensor_truth = truth.T_map_sensor[q.frame];
  o.T_map_sensor_truth = T_map_sensor_truth;
  o.time_s = truth.sequence.times()[q.frame];
  o.mapped = distance_to(run.map_trajectory, T_map_sensor_truth.translation()) <= c.thresholds.mapped_radius_m;
  score(o, reply.T_map_local * q.T_odom_sensor, T_map_sensor_truth, c.thresholds);
  if (reply.detail && reply.detail->estimate) {
    o.method = api::to_string(static_cast<api::ReplyMethod>(reply.detail->estimate->method));
    score_covariance(o, api::covariance_matrix(reply.detail->estimate->covariance_upper));
  }
  return o;
}

void print_outcome(const QueryOutcome& o, const api::LocalizeReply& reply) {
  std::printf(
      "frame %5zu  %7.1f m  %-8s %-13s %s %-12s inliers %3u support %3u conf %.2f  error %6.3f m %5.2f deg  "
      "sigma %5.3f m (%4.1f)  warp %5.2f m %4.2f deg  %6.1f ms%s%s\n",
      o.frame, o.odometer_m, o.mode.c_str(), o.status.c_str(), o.localized ? (o.correct ? "TRUE " : "FALSE") : "     ",
      o.localized ? o.method.c_str() : "", reply.inliers, reply.support, reply.confidence, o.error_m, o.error_deg,
      o.sigma_h_m, o.mahalanobis_h, o.window_warp_m, o.window_warp_deg, o.latency_ms,
      o.mapped ? (o.rejected ? "  (rejected by the tracker)" : "")
               : (o.rejected ? "  (unmapped street; rejected by the tracker)" : "  (unmapped street)"),
      reply.reason.empty() ? "" : ("  " + reply.reason).c_str());
}

// The figures over every outcome: the summary, availability after the first fix (mapped and
// unmapped streets apart), server time by query mode and per module.
void summarize_run(const std::map<std::string, std::vector<double>>& timings, LocalizationRun& run) {
  run.summary = summarize(run.outcomes);
  std::map<std::string, std::vector<double>> by_mode;
  bool fixed = false;
  for (const QueryOutcome& o : run.outcomes) {
    by_mode[o.mode].push_back(o.server_ms);
    if (fixed && o.mapped) ++run.after_first_fix, run.localized_after_first_fix += o.localized;
    if (fixed && !o.mapped) ++run.unmapped_after_first_fix, run.unmapped_localized_after_first_fix += o.localized;
    fixed = fixed || o.localized;
  }
  for (auto& [mode, values] : by_mode) run.server_ms_by_mode[mode] = distribution_of(values);
  for (auto& [name, values] : timings) run.module_ms[name] = distribution_of(values);
}

}  // namespace

LocalizationRun run_localization(const LocalizationRunConfig& c, const LocalizeFn& localize) {
  const storage::MapReader map = storage::MapReader::open(c.map_path);
  LocalizationRun run;
  // The vehicle accumulates and voxelizes exactly as the map was built.
  run.replay = c.replay;
  const io::PipelineConfig parameters = io::parse_map_parameters(map.metadata().parameters_json, c.map_path);
  run.replay.local_cloud = parameters.local_cloud;
  if (c.max_scan_age_m >= 0.0) run.replay.local_cloud.max_scan_age_m = c.max_scan_age_m;
  run.replay.voxel = parameters.localizer.segmentation.voxel;
  for (const storage::Keyframe& k : map.trajectory()) run.map_trajectory.push_back(k.T_map_sensor.translation());
  if (!c.reference_path.empty() && !c.sim_dataset.empty()) throw std::runtime_error("--reference needs --query");
  const Truth truth = open_truth(c);
  run.reference_file = !c.sim_dataset.empty()      ? "ground_truth/lidar_poses_01.txt"
                       : !c.reference_path.empty() ? c.reference_path
                       : truth.sequence.layout() == io::SequenceLayout::kBag
                           ? truth.sequence.source_note()
                           : (fs::path(c.query_folder) / "poses.txt").string();
  const std::optional<io::Sequence> odometry = open_cloud_poses(c, truth, run);
  QueryPriors priors(c, truth.T_map_sensor);
  const double max_track_radius_m = max_tracked_radius_m(parameters.localizer);
  PriorComparison comparison;
  run.title = map.metadata().name + ": " + (c.sim_dataset.empty() ? c.query_folder : c.sim_dataset + " (01)");
  std::map<std::string, std::vector<double>> timings;
  std::unique_ptr<cli::Progress> progress;
  io::replay_sequence(
      odometry ? *odometry : truth.sequence, run.replay,
      [&](const io::ReplayQuery& q) {
        api::LocalizeRequest request = request_of(q);
        const std::string mode = priors.prepare(request, q);
        // A narrow prior with the newest scans: track on the surface layer first (revision 11;
        // the segments path sends its own tracking request instead, eval_main.cpp).
        if (c.track_surfaces) api::ask_to_track_first(request, max_track_radius_m);
        const auto start = std::chrono::steady_clock::now();
        const api::LocalizeReply reply = localize(request);
        const double latency_ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        const bool rejected = priors.update(reply, q);
        if (c.compare_global) comparison.add(request, reply, localize);
        run.outcomes.push_back(outcome_of(q, reply, mode, rejected, latency_ms, truth, run, c));
        add_timings(timings, reply.timings);
        if (c.print_each) print_outcome(run.outcomes.back(), reply);
        return true;
      },
      [&](size_t done, size_t total) {
        if (!progress) progress = std::make_unique<cli::Progress>("replay", total, "scans");
        progress->update(done);
      });
  if (progress) progress->finish();
  summarize_run(timings, run);
  comparison.write_to(run);
  return run;
}

void print_summary(const LocalizationRun& run) {
  const Summary& s = run.summary;
  std::printf("\n== %s\n", run.title.c_str());
  if (run.replay.single_scan)
    std::printf("queries: single raw scans (no accumulation), one every %.1f m\n", run.replay.every_m);
  else if (run.cloud_poses == io::CloudPoses::kOdometry)
    std::printf("local clouds: the vehicle's odometry (%s); the reference (%s) only scores\n",
                run.cloud_poses_file.c_str(), run.reference_file.c_str());
  else
    std::printf(
        "local clouds: the REFERENCE poses (%s), a comparison only: no vehicle has them, and they flatter "
        "every figure below\n",
        run.cloud_poses_file.c_str());
  std::printf("queries %zu (%zu on mapped streets): %zu localized, %zu true, %zu false (> %.1f m or %.1f deg)\n",
              s.queries, s.mapped_queries, s.localized, s.correct, s.false_localizations,
              Thresholds{}.false_translation_m, Thresholds{}.false_rotation_deg);
  std::printf("error of true localizations: median %.3f m / %.2f deg, p90 %.3f m / %.2f deg, max %.3f m / %.2f deg\n",
              s.error_m.median, s.error_deg.median, s.error_m.p90, s.error_deg.p90, s.error_m.max, s.error_deg.max);
  std::printf("P(x): %.0f m driven on mapped streets, 95%% of it within %.0f m of the last true localization\n",
              s.px.total_m, s.px.x95_m);
  std::printf("latency per query: median %.1f ms, p90 %.1f ms, max %.1f ms\n", s.latency_ms.median, s.latency_ms.p90,
              s.latency_ms.max);
  std::printf(
      "after the first localization: %zu of %zu queries on mapped streets localized (%.1f %%); on unmapped "
      "streets %zu of %zu\n",
      run.localized_after_first_fix, run.after_first_fix,
      run.after_first_fix ? 100.0 * run.localized_after_first_fix / run.after_first_fix : 0.0,
      run.unmapped_localized_after_first_fix, run.unmapped_after_first_fix);
  if (s.rejected > 0)
    std::printf("tracker: %zu LOCALIZED answers rejected by its gate, %zu of them false\n", s.rejected,
                s.rejected_false);
  std::printf("answered by:");
  for (const auto& [method, n] : s.localized_by_method) std::printf(" %s %zu", method.c_str(), n);
  std::printf("\n");
  if (s.with_covariance > 0)
    std::printf(
        "covariance: %zu of %zu localized queries have their horizontal error within the reported 3 sigma "
        "(%.1f %%); reported 1-sigma median %.3f m, p90 %.3f m\n",
        s.within_3_sigma, s.with_covariance, 100.0 * s.within_3_sigma / s.with_covariance, s.sigma_h_m.median,
        s.sigma_h_m.p90);
  for (const auto& [mode, d] : run.server_ms_by_mode)
    std::printf("server time, %s queries: %zu, median %.1f ms, p90 %.1f ms\n", mode.c_str(), d.count, d.median, d.p90);
  if (run.ab_prior_server_ms.count > 0)
    std::printf(
        "same queries with and without their prior (%zu): server %.1f vs %.1f ms median, retrieve+classify+verify "
        "%.1f vs %.1f ms median (%.0f %%)\n",
        run.ab_prior_server_ms.count, run.ab_prior_server_ms.median, run.ab_global_server_ms.median,
        run.ab_prior_match_ms.median, run.ab_global_match_ms.median,
        run.ab_global_match_ms.median > 0 ? 100.0 * run.ab_prior_match_ms.median / run.ab_global_match_ms.median : 0.0);
  std::printf("module medians (ms):");
  for (const auto& [name, d] : run.module_ms) std::printf(" %s %.1f", name.c_str(), d.median);
  std::printf("\n");
}

// estimated.tum: T_map_sensor of every localized query; reference.tum: the reference pose of the
// same queries, same times. `evo_ape tum reference.tum estimated.tum` compares them.
namespace {

void write_trajectories_for_evo(const std::vector<QueryOutcome>& outcomes, const std::string& out_dir) {
  io::StampedPoses estimated, reference;
  for (const QueryOutcome& o : outcomes) {
    if (!o.localized) continue;
    estimated.times.push_back(o.time_s);
    estimated.poses.push_back(o.T_map_sensor);
    reference.times.push_back(o.time_s);
    reference.poses.push_back(o.T_map_sensor_truth);
  }
  io::write_tum((std::filesystem::path(out_dir) / "estimated.tum").string(), estimated);
  io::write_tum((std::filesystem::path(out_dir) / "reference.tum").string(), reference);
}

}  // namespace

void write_localization_report(const LocalizationRun& run, const std::string& out_dir) {
  namespace fs = std::filesystem;
  fs::create_directories(out_dir);
  auto dist = [](const Distribution& d) {
    return nlohmann::json{{"count", d.count}, {"median", d.median}, {"p90", d.p90}, {"max", d.max}, {"mean", d.mean}};
  };
  const Summary& s = run.summary;
  nlohmann::json j;
  j["title"] = run.title;
  j["replay"] = {{"every_m", run.replay.every_m}, {"warmup_m", run.replay.warmup_m},
                 {"first", run.replay.first},     {"last", run.replay.last},
                 {"stride", run.replay.stride},   {"single_scan", run.replay.single_scan}};
  j["local_clouds"] = {{"poses", io::to_string(run.cloud_poses)}, {"file", run.cloud_poses_file}};
  j["reference"] = run.reference_file;
  j["queries"] = s.queries;
  j["mapped_queries"] = s.mapped_queries;
  j["localized"] = s.localized;
  j["true_localizations"] = s.correct;
  j["false_localizations"] = s.false_localizations;
  j["error_m"] = dist(s.error_m);
  j["error_deg"] = dist(s.error_deg);
  j["latency_ms"] = dist(s.latency_ms);
  j["px"] = {{"total_mapped_m", s.px.total_m}, {"x95_m", s.px.x95_m}, {"gaps_m", s.px.gaps_m}};
  j["after_first_fix"] = {{"queries", run.after_first_fix},
                          {"localized", run.localized_after_first_fix},
                          {"unmapped_queries", run.unmapped_after_first_fix},
                          {"unmapped_localized", run.unmapped_localized_after_first_fix}};
  j["localized_by_method"] = s.localized_by_method;
  j["rejected_by_tracker"] = {{"answers", s.rejected}, {"false", s.rejected_false}};
  j["calibration"] = {
      {"with_covariance", s.with_covariance}, {"within_3_sigma", s.within_3_sigma}, {"sigma_h_m", dist(s.sigma_h_m)}};
  for (const auto& [mode, d] : run.server_ms_by_mode) j["server_ms_by_mode"][mode] = dist(d);
  if (run.ab_prior_server_ms.count > 0)
    j["same_queries_with_and_without_prior"] = {{"prior_server_ms", dist(run.ab_prior_server_ms)},
                                                {"prior_retrieve_classify_verify_ms", dist(run.ab_prior_match_ms)},
                                                {"global_server_ms", dist(run.ab_global_server_ms)},
                                                {"global_retrieve_classify_verify_ms", dist(run.ab_global_match_ms)}};
  for (const auto& [name, d] : run.module_ms) j["module_ms"][name] = dist(d);
  for (const QueryOutcome& o : run.outcomes) {
    nlohmann::json q = {{"frame", o.frame},
                        {"odometer_m", o.odometer_m},
                        {"mapped", o.mapped},
                        {"status", o.status},
                        {"correct", o.correct},
                        {"error_m", o.error_m},
                        {"error_deg", o.error_deg},
                        {"latency_ms", o.latency_ms},
                        {"inliers", o.inliers},
                        {"support", o.support},
                        {"confidence", o.confidence},
                        {"mode", o.mode},
                        {"server_ms", o.server_ms},
                        {"window_warp_m", o.window_warp_m},
                        {"window_warp_deg", o.window_warp_deg},
                        {"window_points", o.window_points},
                        {"method", o.method},
                        {"rejected_by_tracker", o.rejected}};
    if (o.has_covariance) q["sigma_h_m"] = o.sigma_h_m, q["mahalanobis_h"] = o.mahalanobis_h;
    if (o.localized) {
      const Eigen::Quaterniond r(o.T_map_sensor.linear());
      const Eigen::Vector3d& t = o.T_map_sensor.translation();
      q["T_map_sensor"] = {{"t", {t.x(), t.y(), t.z()}}, {"q_wxyz", {r.w(), r.x(), r.y(), r.z()}}};
    }
    j["per_query"].push_back(q);
  }
  const std::string json_path = (fs::path(out_dir) / "localization.json").string();
  std::ofstream f(json_path);
  f << j.dump(2) << "\n";
  if (!f) throw std::runtime_error(json_path + ": cannot write");
  write_trajectories_for_evo(run.outcomes, out_dir);
  plot_trajectory((fs::path(out_dir) / "trajectory.png").string(), run.map_trajectory, run.outcomes, run.title);
  plot_px((fs::path(out_dir) / "px.png").string(), s.px, "P(x), equation 1: " + run.title);
  plot_error_histogram((fs::path(out_dir) / "errors.png").string(), run.outcomes, "Translation errors: " + run.title);
}

}  // namespace eval
}  // namespace segmatch
