#include "server_bench_world.h"

#include <segmatch/core/mapping/surface_layer.h>
#include <segmatch/core/preprocess/preprocess.h>
#include <segmatch/sim/keyframes.h>
#include <segmatch/sim/local_clouds.h>
#include <segmatch/storage/map_writer.h>

#include <unistd.h>

#include <deque>
#include <filesystem>
#include <map>
#include <set>

namespace segmatch::bench {

std::vector<api::LocalizeRequest> revisit_requests(const sim::City& city, const LocalCloudConfig& local_cloud,
                                                   const VoxelGridConfig* voxel, double every_m) {
  const sim::RayCaster caster(city.changed.scene());
  // The vehicle's local frame and odometry: drifting as sim::KeyframeConfig's defaults.
  Poses truth_local;
  for (const Pose3d& T : city.second.T_world_lidar)
    truth_local.push_back(city.second.T_world_lidar.front().inverse() * T);
  const Poses odometry = sim::drifted_odometry(truth_local, sim::KeyframeConfig{});
  sim::LocalCloudSchedule schedule;
  schedule.every_m = every_m;
  schedule.odometry = &odometry;
  std::vector<api::LocalizeRequest> out;
  // The vehicle's newest scans (the last newest_m of kept scans, placed by its odometry, thinned
  // to 0.2 m as segmatch-eval sends them) at each query's frame: a second pass over the same scans.
  constexpr double kNewestM = 10.0;
  std::map<size_t, PointCloud> newest_at;
  {
    std::deque<std::pair<size_t, PointCloud>> recent;  // (frame, points in the odometry frame)
    std::set<size_t> query_frames;
    sim::for_each_local_cloud(caster, sim::hdl64e(), city.second, local_cloud, schedule,
                              [&](const sim::SimulatedLocalCloud& lc) { query_frames.insert(lc.frame); });
    VoxelGridConfig thin;
    thin.leaf_m = 0.2f;
    thin.min_points_per_voxel = 1;
    auto emit_before = [&](size_t frame) {  // query frames up to `frame` see the scans kept so far
      while (!query_frames.empty() && *query_frames.begin() <= frame) {
        PointCloud all;
        for (const auto& kept : recent) all.insert(all.end(), kept.second.begin(), kept.second.end());
        newest_at[*query_frames.begin()] = voxel_filter(all, thin);
        query_frames.erase(query_frames.begin());
      }
    };
    sim::for_each_kept_scan(
        caster, sim::hdl64e(), city.second, local_cloud, schedule, [&](size_t frame, const sim::SimulatedScan& scan) {
          if (frame > 0) emit_before(frame - 1);
          PointCloud placed = scan.points;
          for (Point& p : placed) {
            const Eigen::Vector3f q = odometry[frame].cast<float>() * p.xyz();
            p.x = q.x(), p.y = q.y(), p.z = q.z();
          }
          recent.emplace_back(frame, voxel_filter(placed, thin));
          while (city.second.odometer_m[frame] - city.second.odometer_m[recent.front().first] > kNewestM)
            recent.pop_front();
          emit_before(frame);
        });
    emit_before(SIZE_MAX);
  }
  sim::for_each_local_cloud(caster, sim::hdl64e(), city.second, local_cloud, schedule,
                            [&](const sim::SimulatedLocalCloud& lc) {
                              api::LocalizeRequest r;
                              r.request_id = lc.frame;
                              r.sensor_position_local = lc.T_cloud_sensor.translation();
                              // The truth's T_map_local at the sensor (map frame = world frame), for the tracked
                              // level's priors; not sent without kFlagHasPrior.
                              r.T_map_local_prior = lc.T_world_sensor * lc.T_cloud_sensor.inverse();
                              r.points = lc.cloud;
                              if (const auto n = newest_at.find(lc.frame); n != newest_at.end())
                                r.newest_points = n->second;  // sent with bit 5 only
                              // What a vehicle sends (docs/protocol.md 5.4): its local cloud voxelized with the map's
                              // grid.
                              if (voxel) {
                                r.points = voxel_filter(r.points, *voxel);
                                r.flags |= api::kFlagVoxelized;
                              }
                              out.push_back(std::move(r));
                            });
  return out;
}

std::string build_map(const sim::City& city, const io::PipelineConfig& config, const std::string& model) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("segmatch_bench_server_" + std::to_string(::getpid()) + ".sqlite"))
          .string();
  sim::SegmentsAlongConfig along;
  along.schedule.every_m = 5.0;
  along.segmentation = config.localizer.segmentation;
  along.local_cloud = config.local_cloud;
  storage::MapMetadata meta;
  meta.name = "bench-tiny";
  meta.parameters_json = io::to_json(config);
  storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
  writer.add_segments(sim::segments_along(city.world, city.first, sim::hdl64e(), along), {});
  // The surface layer, as segmatch-mapbuilder accumulates it from the first traversal's scans.
  SurfaceAccumulator surfaces(config.surfaces);
  const sim::RayCaster caster(city.world.scene());
  sim::for_each_kept_scan(caster, sim::hdl64e(), city.first, config.local_cloud, sim::LocalCloudSchedule{},
                          [&](size_t frame, const sim::SimulatedScan& scan) {
                            surfaces.add_scan(scan.points, city.first.T_world_lidar[frame]);
                          });
  writer.set_surfaces(surfaces.points(), config.surfaces.leaf_m, config.surfaces.tile_m);
  if (!model.empty()) writer.set_classifier({storage::kClassifierFormatRTreesYaml, model});
  writer.commit();
  return path;
}

}  // namespace segmatch::bench
