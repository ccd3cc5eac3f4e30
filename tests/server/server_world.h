// The server suites' world: a simulated tiny city, its map written with storage::MapWriter (L2
// matcher, eigen features only, so the suites stay fast) and revisit queries in the vehicle's
// odometry frame with their ground truth. tests/fixtures/make_server_world.cpp builds it into a
// folder once per build (server_test_util.h caches it); the queries are stored as the LOCALIZE
// frames a client sends, with their ground truth beside them.
#pragma once

#include "segmatch/api/protocol.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/sim/city.h"
#include "segmatch/storage/map_writer.h"

#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace segmatch::testing {

struct Query {
  size_t frame = 0;
  api::LocalizeRequest request;
  Pose3d T_local_sensor, T_world_sensor;  // ground truth (map frame = world frame)
};

inline io::PipelineConfig fast_config() {
  io::PipelineConfig c = io::pipeline_preset("kitti-hdl64");
  c.localizer.segmentation.descriptors.compute_esf = false;
  c.localizer.matcher.type = MatcherType::kL2;
  c.localizer.matcher.use_shapes = false;
  // The preset's 0.8 confidence floor was chosen for the RF matcher on the demo's dense map;
  // with L2 on this short map true poses reach only 0.46-0.79 (4 of 9 revisit queries).
  c.localizer.min_confidence = 0.0f;
  // A vehicle thins each scan before accumulating it: full HDL-64E local clouds are 4-14 M
  // points (60-230 MB), over the 64 MiB frame limit and seconds to localize.
  c.local_cloud.subsample_leaf_m = 0.1;
  // The queries are built from the exact simulated poses: nothing drifts, and the age limit
  // (there for a vehicle's odometry) would only thin them (docs/how-defaults-were-chosen.md).
  c.local_cloud.max_scan_age_m = 0.0;
  // For the same reason no recent-window refinement: it corrects the odometry's drift near the
  // sensor, and here there is none. On this small map a window holds a few segments, and
  // refining them alone moved exact poses by up to 0.75 deg (gcc) and 1.26 deg (clang: a
  // sanitizer CI run failed on it), where the whole cloud gives 0.02-0.4 deg.
  c.localizer.refine.recent_window_m = 0.0f;
  return c;
}

inline void write_map(const std::string& path, const io::PipelineConfig& config, const Segments& segments) {
  storage::MapMetadata meta;
  meta.name = "tiny-3";
  meta.tool_version = "test_server";
  meta.parameters_json = io::to_json(config);
  storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
  writer.add_segments(segments, {});
  writer.commit();
}

inline std::vector<Query> revisit_queries(const sim::City& city, const LocalCloudConfig& local_cloud, double every_m,
                                          uint64_t seed) {
  const sim::RayCaster caster(city.changed.scene());
  const Pose3d T_local_world = city.second.T_world_lidar.front().inverse();
  sim::LocalCloudSchedule schedule;
  schedule.every_m = every_m;
  schedule.seed = seed;
  std::vector<Query> out;
  sim::for_each_local_cloud(caster, sim::hdl64e(), city.second, local_cloud, schedule,
                            [&](const sim::SimulatedLocalCloud& lc) {
                              Query q;
                              q.frame = lc.frame;
                              q.T_world_sensor = lc.T_world_sensor;
                              q.T_local_sensor = T_local_world * lc.T_world_sensor;
                              q.request.request_id = lc.frame;
                              q.request.sensor_position_local = q.T_local_sensor.translation();
                              q.request.sensor_orientation_local = Eigen::Quaterniond(q.T_local_sensor.linear());
                              q.request.points = lc.cloud;
                              for (Point& p : q.request.points) {
                                const Eigen::Vector3f v = T_local_world.cast<float>() * p.xyz();
                                p.x = v.x(), p.y = v.y(), p.z = v.z();
                              }
                              out.push_back(std::move(q));
                            });
  return out;
}

// queries.bin: per query its frame (u64), T_local_sensor and T_world_sensor (16 doubles each,
// column-major), the LOCALIZE frame's size (u64) and the frame (api::encode).
inline void write_queries(const std::string& path, const std::vector<Query>& queries) {
  std::ofstream out(path, std::ios::binary);
  auto put = [&](const void* p, size_t n) { out.write(static_cast<const char*>(p), static_cast<std::streamsize>(n)); };
  for (const Query& q : queries) {
    const uint64_t frame = q.frame;
    put(&frame, sizeof frame);
    put(q.T_local_sensor.matrix().data(), 16 * sizeof(double));
    put(q.T_world_sensor.matrix().data(), 16 * sizeof(double));
    const std::vector<uint8_t> bytes = api::encode(q.request);
    const uint64_t size = bytes.size();
    put(&size, sizeof size);
    put(bytes.data(), bytes.size());
  }
  if (!out.flush()) throw std::runtime_error("cannot write " + path);
}

inline std::vector<Query> read_queries(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  auto get = [&](void* p, size_t n) {
    return static_cast<bool>(in.read(static_cast<char*>(p), static_cast<std::streamsize>(n)));
  };
  std::vector<Query> out;
  for (uint64_t frame = 0; get(&frame, sizeof frame);) {
    Query q;
    q.frame = frame;
    uint64_t size = 0;
    if (!get(q.T_local_sensor.matrix().data(), 16 * sizeof(double)) ||
        !get(q.T_world_sensor.matrix().data(), 16 * sizeof(double)) || !get(&size, sizeof size) || size > (1u << 30))
      throw std::runtime_error(path + ": truncated query");
    std::vector<uint8_t> bytes(size);
    if (!get(bytes.data(), size) || api::decode_frame(bytes, api::Limits{}, q.request) != api::DecodeStatus::kOk)
      throw std::runtime_error(path + ": bad LOCALIZE frame");
    out.push_back(std::move(q));
  }
  return out;
}

// Writes tiny.sqlite and queries.bin into `folder`.
inline void build_server_world(const std::string& folder) {
  const io::PipelineConfig config = fast_config();
  const sim::City city = sim::make_city(sim::dataset_preset("tiny", 3));
  sim::SegmentsAlongConfig along;
  along.schedule.every_m = 8.0;
  along.schedule.seed = 21;
  along.local_cloud = config.local_cloud;
  along.segmentation = config.localizer.segmentation;
  write_map(folder + "/tiny.sqlite", config, sim::segments_along(city.world, city.first, sim::hdl64e(), along));
  write_queries(folder + "/queries.bin", revisit_queries(city, config.local_cloud, 15.0, 31));
}

}  // namespace segmatch::testing
