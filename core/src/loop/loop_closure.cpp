#include "segmatch/core/loop/loop_closure.h"

#include "loop/loop_map.h"
#include "segmatch/core/preprocess/voxel_accumulator.h"

#include <chrono>
#include <cmath>
#include <map>
#include <stdexcept>
#include <unordered_map>

namespace segmatch {
namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

bool finite_pose(const Pose3d& T) { return T.matrix().allFinite(); }

}  // namespace

void LoopDetectorConfig::validate() const {
  local_cloud.validate();
  localizer.validate();
  segment_map.validate();
  if (!(local_cloud_every_m > 0.0) || !std::isfinite(local_cloud_every_m))
    throw std::invalid_argument("local_cloud_every_m must be finite and > 0");
  if (!(exclude_recent_distance_m >= 0.0) || !std::isfinite(exclude_recent_distance_m))
    throw std::invalid_argument("exclude_recent_distance_m must be finite and >= 0");
  if (!(exclude_recent_time_s >= 0.0) || !std::isfinite(exclude_recent_time_s))
    throw std::invalid_argument("exclude_recent_time_s must be finite and >= 0");
  if (exclude_recent_distance_m <= 0.0 && exclude_recent_time_s <= 0.0)
    throw std::invalid_argument("exclude_recent_distance_m or exclude_recent_time_s must be > 0");
  if (!(local_cloud_history_m > 0.0) || !std::isfinite(local_cloud_history_m))
    throw std::invalid_argument("local_cloud_history_m must be finite and > 0");
  if (exclude_recent_distance_m > 0.0 && local_cloud_history_m > exclude_recent_distance_m)
    throw std::invalid_argument("local_cloud_history_m must not exceed exclude_recent_distance_m");
  if (min_inliers < 1) throw std::invalid_argument("min_inliers must be >= 1");
  if (!(min_confidence >= 0.0f && min_confidence <= 1.0f))
    throw std::invalid_argument("min_confidence must be in 0..1");
  if (rebuild_every_local_clouds < 1) throw std::invalid_argument("rebuild_every_local_clouds must be >= 1");
  if (!(max_drift_m >= 0.0) || !std::isfinite(max_drift_m))
    throw std::invalid_argument("max_drift_m must be finite and >= 0 (0: no bound)");
  if (!(max_drift_fraction >= 0.0 && max_drift_fraction < 1.0))
    throw std::invalid_argument("max_drift_fraction must be in [0, 1) (0: a fixed bound)");
  if (!(max_drift_deg >= 0.0) || !std::isfinite(max_drift_deg))
    throw std::invalid_argument("max_drift_deg must be finite and >= 0");
}

struct LoopDetector::Impl {
  LoopDetectorConfig config;
  std::shared_ptr<const RandomForestMatcher> classifier;
  // Two local clouds restarted alternately every local_cloud_history_m, half of it apart; the
  // query uses the one with the longer history. Voxelized incrementally (as the map builder):
  // voxel_filter of a crop of millions of raw points was a third of a step's time.
  VoxelAccumulator local[2];
  double local_started_at[2];
  LoopSegmentMap map;
  // Localizer over the eligible (old, frozen) segments and, per target, its map index.
  std::unique_ptr<Localizer> localizer;
  std::vector<int> target_map_index;
  int clouds_since_build = 0;
  // Odometry pose, odometer and time of each processed local cloud, by frame.
  struct CloudPose {
    Pose3d T_odom_sensor;
    double odometer_m, time_s;
  };
  std::unordered_map<size_t, CloudPose> cloud_poses;
  std::vector<LoopClosure> loops;
  bool has_last = false;
  size_t last_frame = 0;
  Pose3d T_odom_last = Pose3d::Identity();
  double odometer = 0.0;
  double next_cloud_at;

  Impl(const LoopDetectorConfig& c, std::shared_ptr<const RandomForestMatcher> rf)
      : config(c),
        classifier(std::move(rf)),
        local{VoxelAccumulator(c.local_cloud, c.localizer.segmentation.voxel),
              VoxelAccumulator(c.local_cloud, c.localizer.segmentation.voxel)},
        local_started_at{0.0, -0.5 * c.local_cloud_history_m},
        map(c.segment_map, RecencyWindow{c.exclude_recent_distance_m, c.exclude_recent_time_s}),
        next_cloud_at(c.local_cloud_every_m) {}

  void advance_odometer(const Pose3d& T_odom_sensor, size_t frame);
  void accumulate(const PointCloud& scan, const Pose3d& T_odom_sensor);
  VoxelAccumulator& longest_history() { return local_started_at[0] <= local_started_at[1] ? local[0] : local[1]; }
  bool rebuild_if_due(const Sighting& now);
  void match(const PointCloud& cloud, const Pose3d& T_odom_sensor, const Sighting& now, LoopStep& step,
             Segments& query);
  std::optional<LoopClosure> to_loop(const LocalizationResult& r, const Sighting& now,
                                     const Pose3d& T_odom_query) const;
};

void LoopDetector::Impl::advance_odometer(const Pose3d& T_odom_sensor, size_t frame) {
  if (!finite_pose(T_odom_sensor))
    throw std::invalid_argument("T_odom_sensor of frame " + std::to_string(frame) + " is not finite");
  if (has_last && frame <= last_frame)
    throw std::invalid_argument("frame indices must increase (got " + std::to_string(frame) + " after " +
                                std::to_string(last_frame) + ")");
  if (has_last) odometer += (T_odom_sensor.translation() - T_odom_last.translation()).norm();
  has_last = true;
  last_frame = frame;
  T_odom_last = T_odom_sensor;
}

void LoopDetector::Impl::accumulate(const PointCloud& scan, const Pose3d& T_odom_sensor) {
  for (int k = 0; k < 2; ++k) {
    if (odometer - local_started_at[k] >= config.local_cloud_history_m) {
      local[k].clear();
      local_started_at[k] = odometer;
    }
    local[k].add_scan(scan, T_odom_sensor);
  }
}

// Rebuilds the localizer over the segments that left the recent-past window, when due and
// when that set grew (it never shrinks: old segments are frozen, see loop_closure.h).
bool LoopDetector::Impl::rebuild_if_due(const Sighting& now) {
  ++clouds_since_build;
  if (localizer && clouds_since_build < config.rebuild_every_local_clouds) return false;
  std::vector<int> eligible = map.eligible(now);
  if (eligible.empty() || eligible.size() == target_map_index.size()) return false;
  Segments targets;
  targets.reserve(eligible.size());
  for (int i : eligible) targets.push_back(map.segments()[i]);
  // Loop closures are found by segment matching alone (the paper's method): registration
  // around the odometry's guess (registration.h) is tracking against a prior map, and a loop's
  // drift can exceed its basin.
  LocalizerConfig segments_only = config.localizer;
  segments_only.registration.enabled = false;
  // Its odometry prior is no tracker's: the loop's own floors (min_inliers, min_confidence, the
  // drift bound) decide, as measured on hku-loop1 and hku-mb, not the localizer's floors for
  // priors (raised for tracking against wrong priors).
  segments_only.min_support_with_prior = -1;
  localizer = std::make_unique<Localizer>(segments_only, std::move(targets), classifier);
  target_map_index = std::move(eligible);
  clouds_since_build = 0;
  return true;
}

// The loop a localization result describes, if it is one: the match frame is the local cloud
// the majority of the matched target segments' points come from (their kept view), so that the
// edge relates the query to the odometry pose whose drift those points carry. (The last
// sighting would be wrong by the drift in between: on hku-loop1 objects seen from frame 10 on
// were last seen at frame 112.)
std::optional<LoopClosure> LoopDetector::Impl::to_loop(const LocalizationResult& r, const Sighting& now,
                                                       const Pose3d& T_odom_query) const {
  std::map<size_t, int> votes;
  for (const Match& m : r.inliers) ++votes[map.view_frames()[target_map_index[m.target]]];
  size_t match_frame = 0;
  int best = -1;
  for (const auto& [frame, n] : votes)
    if (n > best) best = n, match_frame = frame;  // ties: the earlier frame
  const CloudPose& old = cloud_poses.at(match_frame);
  LoopClosure loop;
  loop.query_frame = now.frame;
  loop.match_frame = match_frame;
  loop.query_time_s = now.time_s;
  loop.match_time_s = old.time_s;
  loop.query_odometer_m = now.odometer_m;
  loop.match_odometer_m = old.odometer_m;
  loop.T_oldodom_odom = r.T_map_query;
  // A point p_q of the query sensor lies at T_odom_query * p_q in the query's odometry
  // coordinates, at T_oldodom_odom * T_odom_query * p_q in the old view's, where the old
  // sensor sees it at T_odom_match^-1 of that.
  const Pose3d T_match_query = old.T_odom_sensor.inverse() * r.T_map_query * T_odom_query;
  loop.T_query_match = T_match_query.inverse();
  loop.inliers = r.inliers.size();
  loop.support = r.support;
  loop.confidence = r.confidence;
  return loop;
}

void LoopDetector::Impl::match(const PointCloud& cloud, const Pose3d& T_odom_sensor, const Sighting& now,
                               LoopStep& step, Segments& query) {
  const Eigen::Vector3f sensor = T_odom_sensor.translation().cast<float>();
  if (!localizer) {
    query = extract_segments_from_voxels(cloud, sensor, config.localizer.segmentation, nullptr, &step.timings);
    step.reason = "no target segments older than the recent-past window yet";
    return;
  }
  step.eligible_targets = localizer->targets().size();
  // The map is in the odometry frame: the odometry's own guess is the identity.
  const double bound_m = config.drift_bound_m(now.odometer_m);
  const PosePrior odometry{Pose3d::Identity(), bound_m, config.max_drift_deg};
  LocalizationResult r = localizer->localize(cloud, sensor, CloudKind::kVoxelized, bound_m > 0.0 ? &odometry : nullptr);
  step.timings = r.timings;
  query = std::move(r.query);
  if (!r.localized()) {
    step.reason = r.reason;
    return;
  }
  if (r.inliers.size() < static_cast<size_t>(config.min_inliers)) {
    step.reason = "only " + std::to_string(r.inliers.size()) + " inliers (at least " +
                  std::to_string(config.min_inliers) + " needed)";
    return;
  }
  if (r.confidence < config.min_confidence) {
    step.reason = "confidence " + std::to_string(r.confidence) + " below " + std::to_string(config.min_confidence);
    return;
  }
  step.loop = to_loop(r, now, T_odom_sensor);
}

LoopDetector::LoopDetector(const LoopDetectorConfig& config, std::shared_ptr<const RandomForestMatcher> classifier) {
  config.validate();
  if (config.localizer.matcher.type == MatcherType::kRandomForest && !(classifier && classifier->trained()))
    throw std::invalid_argument("the random forest matcher needs a trained classifier");
  impl_ = std::make_unique<Impl>(config, std::move(classifier));
}

LoopDetector::~LoopDetector() = default;
LoopDetector::LoopDetector(LoopDetector&&) noexcept = default;
LoopDetector& LoopDetector::operator=(LoopDetector&&) noexcept = default;

LoopStep LoopDetector::process(const PointCloud& scan_points_sensor, const Pose3d& T_odom_sensor, size_t frame_index,
                               double time_s) {
  const auto start = std::chrono::steady_clock::now();
  Impl& d = *impl_;
  d.advance_odometer(T_odom_sensor, frame_index);
  d.accumulate(scan_points_sensor, T_odom_sensor);
  LoopStep step;
  if (d.odometer < d.next_cloud_at) return step;
  d.next_cloud_at = d.odometer + d.config.local_cloud_every_m;
  step.processed = true;
  const Sighting now{frame_index, d.odometer, time_s};
  d.cloud_poses[frame_index] = {T_odom_sensor, d.odometer, time_s};
  step.rebuilt_index = d.rebuild_if_due(now);
  const auto crop_start = std::chrono::steady_clock::now();
  const PointCloud cloud = d.longest_history().crop(T_odom_sensor);
  const double crop_ms = ms_since(crop_start);
  Segments query;
  d.match(cloud, T_odom_sensor, now, step, query);
  step.timings.voxel_ms = crop_ms;  // the voxel grid's share: the incremental grid's crop
  step.query_segments = query.size();
  d.map.add(std::move(query), now);
  step.map_segments = d.map.size();
  if (step.loop) d.loops.push_back(*step.loop);
  step.total_ms = ms_since(start);
  return step;
}

const LoopDetectorConfig& LoopDetector::config() const { return impl_->config; }
double LoopDetector::odometer_m() const { return impl_->odometer; }
size_t LoopDetector::map_size() const { return impl_->map.size(); }
const std::vector<LoopClosure>& LoopDetector::loops() const { return impl_->loops; }
Segments LoopDetector::map_segments() const { return impl_->map.segments(); }
std::vector<size_t> LoopDetector::map_segment_frames() const { return impl_->map.view_frames(); }

}  // namespace segmatch
