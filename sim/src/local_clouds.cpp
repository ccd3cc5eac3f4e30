#include "segmatch/sim/local_clouds.h"

#include "segmatch/core/preprocess/voxel_accumulator.h"

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <thread>

namespace segmatch::sim {
namespace {

// Frames the local cloud will keep: the first, then one per min_travel metres.
std::vector<size_t> kept_frames(const Traversal& t, size_t first, size_t last, double min_travel_m) {
  std::vector<size_t> frames;
  for (size_t i = first; i <= last && i < t.size(); ++i) {
    if (frames.empty() ||
        (t.T_world_lidar[i].translation() - t.T_world_lidar[frames.back()].translation()).norm() >= min_travel_m)
      frames.push_back(i);
  }
  return frames;
}

std::vector<SimulatedScan> simulate_batch(const RayCaster& caster, const LidarModel& model, const Traversal& t,
                                          const std::vector<size_t>& frames, uint64_t seed, int threads) {
  std::vector<SimulatedScan> scans(frames.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k; (k = next++) < frames.size();)
      scans[k] = simulate_scan(caster, model, t.T_world_lidar[frames[k]], mix_seed(seed, frames[k]));
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < threads; ++i) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();
  return scans;
}

}  // namespace

void for_each_kept_scan(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                        const LocalCloudConfig& local_config, const LocalCloudSchedule& schedule,
                        const std::function<void(size_t, const SimulatedScan&)>& visit) {
  const int threads = schedule.threads > 0 ? schedule.threads : std::max(1u, std::thread::hardware_concurrency());
  const size_t last = std::min(schedule.last_frame, traversal.size() - 1);
  const auto frames = kept_frames(traversal, schedule.first_frame, last, local_config.min_travel_between_scans_m);
  constexpr size_t kBatch = 16;
  for (size_t b = 0; b < frames.size(); b += kBatch) {
    const std::vector<size_t> batch(frames.begin() + b, frames.begin() + std::min(frames.size(), b + kBatch));
    const auto scans = simulate_batch(caster, model, traversal, batch, schedule.seed, threads);
    for (size_t k = 0; k < batch.size(); ++k) visit(batch[k], scans[k]);
  }
}

namespace {

// The schedule of for_each_local_cloud over any accumulator with LocalCloud's add_scan/crop.
template <class Accumulator>
void visit_local_clouds(Accumulator& local, const RayCaster& caster, const LidarModel& model,
                        const Traversal& traversal, const LocalCloudConfig& local_config,
                        const LocalCloudSchedule& schedule,
                        const std::function<void(const SimulatedLocalCloud&)>& visit) {
  if (schedule.odometry && schedule.odometry->size() != traversal.size())
    throw std::invalid_argument("LocalCloudSchedule.odometry must hold one pose per traversal scan");
  double next_cloud_at = traversal.odometer_m[schedule.first_frame] + schedule.warmup_m;
  for_each_kept_scan(caster, model, traversal, local_config, schedule, [&](size_t f, const SimulatedScan& scan) {
    const Pose3d& T_cloud_sensor = schedule.odometry ? (*schedule.odometry)[f] : traversal.T_world_lidar[f];
    local.add_scan(scan.points, T_cloud_sensor, &scan.labels);
    if (traversal.odometer_m[f] < next_cloud_at) return;
    next_cloud_at = traversal.odometer_m[f] + schedule.every_m;
    SimulatedLocalCloud out;
    out.frame = f;
    out.T_world_sensor = traversal.T_world_lidar[f];
    out.T_cloud_sensor = T_cloud_sensor;
    out.cloud = local.crop(T_cloud_sensor, &out.labels);
    visit(out);
  });
}

}  // namespace

void for_each_local_cloud(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                          const LocalCloudConfig& local_config, const LocalCloudSchedule& schedule,
                          const std::function<void(const SimulatedLocalCloud&)>& visit) {
  LocalCloud local(local_config);
  visit_local_clouds(local, caster, model, traversal, local_config, schedule, visit);
}

void for_each_voxelized_cloud(const RayCaster& caster, const LidarModel& model, const Traversal& traversal,
                              const LocalCloudConfig& local_config, const VoxelGridConfig& voxel,
                              const LocalCloudSchedule& schedule,
                              const std::function<void(const SimulatedLocalCloud&)>& visit) {
  VoxelAccumulator local(local_config, voxel);
  visit_local_clouds(local, caster, model, traversal, local_config, schedule, visit);
}

}  // namespace segmatch::sim
