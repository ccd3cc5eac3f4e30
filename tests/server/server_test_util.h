// A simulated tiny city, its map written with storage::MapWriter (L2 matcher, eigen features
// only, so the suite stays fast) and revisit queries in the vehicle's odometry frame with
// their ground truth. Built once per test executable.
#pragma once

#include "segmatch/api/client.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/server/server.h"
#include "segmatch/sim/city.h"
#include "segmatch/storage/map_writer.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <mutex>

namespace segmatch::testing {

struct Query {
  size_t frame = 0;
  api::LocalizeRequest request;
  Pose3d T_local_sensor, T_world_sensor;  // ground truth (map frame = world frame)
};

struct TestWorld {
  std::string folder, map_path;
  io::PipelineConfig config;
  std::vector<Query> queries;  // revisit local clouds every 15 m
  // The folder goes with the test process unless SEGMATCH_KEEP_TEST_FILES is set (to read the
  // logs of the processes a test ran).
  ~TestWorld() {
    std::error_code ec;
    if (!folder.empty() && !std::getenv("SEGMATCH_KEEP_TEST_FILES")) std::filesystem::remove_all(folder, ec);
  }
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

inline const TestWorld& test_world() {
  static std::once_flag once;
  static std::unique_ptr<TestWorld> world;
  std::call_once(once, [] {
    world = std::make_unique<TestWorld>();
    world->folder = (std::filesystem::temp_directory_path() / ("segmatch_server_test_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(world->folder);
    world->map_path = world->folder + "/tiny.sqlite";
    world->config = fast_config();
    const auto t0 = std::chrono::steady_clock::now();
    auto seconds = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
    const sim::City city = sim::make_city(sim::dataset_preset("tiny", 3));
    std::printf("[server] city %.1f s\n", seconds());
    sim::SegmentsAlongConfig along;
    along.schedule.every_m = 8.0;
    along.schedule.seed = 21;
    along.local_cloud = world->config.local_cloud;
    along.segmentation = world->config.localizer.segmentation;
    write_map(world->map_path, world->config, sim::segments_along(city.world, city.first, sim::hdl64e(), along));
    std::printf("[server] map %.1f s\n", seconds());
    world->queries = revisit_queries(city, world->config.local_cloud, 15.0, 31);
    std::printf("[server] queries %.1f s\n", seconds());
    std::printf("[server] map %s, %zu revisit queries\n", world->map_path.c_str(), world->queries.size());
  });
  return *world;
}

inline double position_error_m(const Pose3d& a, const Pose3d& b) { return (a.translation() - b.translation()).norm(); }
inline double angle_error_deg(const Pose3d& a, const Pose3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
}

// A server on an ephemeral loopback port, log lines kept for inspection.
struct RunningServer {
  explicit RunningServer(server::ServerConfig config = {}) {
    config.listen_address = "127.0.0.1";
    config.port = 0;
    if (config.workers == 0) config.workers = 2;
    config.log = [this](const std::string& line) {
      std::lock_guard<std::mutex> lock(log_mutex);
      log.push_back(line);
    };
    static std::shared_ptr<const server::LoadedMap> map = server::load_map(test_world().map_path);
    server = std::make_unique<server::Server>(config, map);
    server->start();
  }
  api::Client client(const std::string& token = "") const {
    api::ClientOptions o;
    o.token = token;
    o.reply_timeout_s = 60;
    return api::Client("127.0.0.1", server->port(), o);
  }
  ~RunningServer() { server.reset(); }  // its threads log into `log` until they are joined
  std::vector<std::string> log_lines() {
    std::lock_guard<std::mutex> lock(log_mutex);
    return log;
  }
  std::unique_ptr<server::Server> server;
  std::mutex log_mutex;
  std::vector<std::string> log;
};

}  // namespace segmatch::testing
