// segmatch-bench-server: throughput and latency of segmatch-server over loopback with 1, 4
// and 16 concurrent clients, on a simulated tiny city mapped by its first traversal and
// queried with the revisit's voxelized local clouds (HDL-64E, 60 m cylinder), with the shipped
// RF model (or --l2). Closed loop (clients back to back) and open loop (a fleet on fixed
// schedules at an offered rate). Prints figures, asserts nothing.
#include <segmatch/api/client.h>
#include <segmatch/core/preprocess.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/server/server.h>
#include <segmatch/sim/city.h>
#include <segmatch/storage/map_writer.h>

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <thread>

using namespace segmatch;
using Clock = std::chrono::steady_clock;

namespace {

std::vector<api::LocalizeRequest> revisit_requests(const sim::City& city, const LocalCloudConfig& local_cloud,
                                                   const VoxelGridConfig* voxel, double every_m) {
  const sim::RayCaster caster(city.changed.scene());
  const Pose3d T_local_world = city.second.T_world_lidar.front().inverse();
  sim::LocalCloudSchedule schedule;
  schedule.every_m = every_m;
  std::vector<api::LocalizeRequest> out;
  sim::for_each_local_cloud(caster, sim::hdl64e(), city.second, local_cloud, schedule,
                            [&](const sim::SimulatedLocalCloud& lc) {
    api::LocalizeRequest r;
    r.request_id = lc.frame;
    r.sensor_position_local = T_local_world * lc.T_world_sensor.translation();
    r.points = lc.cloud;
    for (Point& p : r.points) {
      const Eigen::Vector3f v = T_local_world.cast<float>() * p.xyz();
      p.x = v.x(), p.y = v.y(), p.z = v.z();
    }
    // What a vehicle sends (docs/protocol.md 5.4): its local cloud voxelized with the map's grid.
    if (voxel) {
      r.points = voxel_filter(r.points, *voxel);
      r.flags |= api::kFlagVoxelized;
    }
    out.push_back(std::move(r));
  });
  return out;
}

std::string build_map(const sim::City& city, const io::PipelineConfig& config, const std::string& model) {
  const std::string path = (std::filesystem::temp_directory_path() / ("segmatch_bench_server_" + std::to_string(::getpid()) + ".sqlite")).string();
  sim::SegmentsAlongConfig along;
  along.schedule.every_m = 5.0;
  along.segmentation = config.localizer.segmentation;
  along.local_cloud = config.local_cloud;
  storage::MapMetadata meta;
  meta.name = "bench-tiny";
  meta.parameters_json = io::to_json(config);
  storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
  writer.add_segments(sim::segments_along(city.world, city.first, sim::hdl64e(), along), {});
  if (!model.empty()) writer.set_classifier({"opencv-rtrees-yaml", model});
  writer.commit();
  return path;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

// What the clients of one level saw: latencies of answered queries, errors, localizations.
struct Tally {
  std::mutex mutex;
  std::vector<double> latencies_ms;
  std::atomic<int> errors{0}, localized{0};

  // One query; its latency counts from `since` (the send, or the scheduled send time).
  void query(api::Client& client, const api::LocalizeRequest& r, Clock::time_point since) {
    try {
      localized += client.localize(r).status == api::LocalizeStatus::kLocalized;
    } catch (const std::exception&) {
      ++errors;
      return;
    }
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - since).count();
    std::lock_guard<std::mutex> lock(mutex);
    latencies_ms.push_back(ms);
  }
  void print(double seconds) const {
    std::printf("%4zu queries in %6.1f s = %6.2f queries/s, latency p50 %7.1f ms p99 %7.1f ms, %d localized, %d errors\n",
                latencies_ms.size(), seconds, latencies_ms.size() / seconds, percentile(latencies_ms, 0.5),
                percentile(latencies_ms, 0.99), localized.load(), errors.load());
  }
};

api::Client connect(uint16_t port) {
  api::ClientOptions options;
  options.reply_timeout_s = 600;
  return api::Client("127.0.0.1", port, options);
}

// `clients` connections, each sending `per_client` queries back to back.
void run_level(uint16_t port, const std::vector<api::LocalizeRequest>& requests, int clients, int per_client) {
  Tally tally;
  const auto start = Clock::now();
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] {
      api::Client client = connect(port);
      for (int i = 0; i < per_client; ++i) tally.query(client, requests[(c * 7 + i) % requests.size()], Clock::now());
    });
  for (std::thread& t : threads) t.join();
  std::printf("%2d clients: ", clients);
  tally.print(std::chrono::duration<double>(Clock::now() - start).count());
}

// A fleet: `clients` vehicles together asking `rate` queries/s, each on its own fixed schedule
// (a vehicle queries every few metres whether or not the previous answer was quick), for
// `seconds`. Latency counts from the scheduled send time, so a queue that builds up shows in
// it (no coordinated omission); a vehicle whose answer is late sends its next query at once.
void run_fleet(uint16_t port, const std::vector<api::LocalizeRequest>& requests, int clients, double rate,
               double seconds) {
  Tally tally;
  const auto start = Clock::now() + std::chrono::milliseconds(200);
  const std::chrono::duration<double> period(clients / rate);
  const int per_client = std::max(1, static_cast<int>(seconds * rate / clients));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] {
      api::Client client = connect(port);
      const auto first = start + std::chrono::duration_cast<Clock::duration>(period * (static_cast<double>(c) / clients));
      for (int i = 0; i < per_client; ++i) {
        const auto due = first + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(i));
        std::this_thread::sleep_until(due);
        tally.query(client, requests[(c * 7 + i) % requests.size()], due);
      }
    });
  for (std::thread& t : threads) t.join();
  std::printf("%2d vehicles at %.1f queries/s offered: ", clients, rate);
  tally.print(std::chrono::duration<double>(Clock::now() - start).count());
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"segmatch-bench-server: loopback throughput and latency of segmatch-server"};
  int workers = 0, queries_per_level = 32;
  uint64_t seed = 3;
  double subsample_leaf_m = 0.0;
  bool raw = false, l2 = false;
  double fleet_rate = 20.0, fleet_seconds = 30.0;
  int fleet_vehicles = 16;
  std::string model_path = SEGMATCH_SOURCE_DIR "/maps/models/default-rf.yml";
  app.add_option("--workers", workers, "server localization threads (0 = cores)");
  app.add_option("--queries", queries_per_level, "queries per level, spread over its clients (at least one each)");
  app.add_option("--seed", seed, "city seed");
  app.add_option("--subsample-leaf-m", subsample_leaf_m, "per-scan subsampling of the local cloud (0 = full scans)");
  app.add_flag("--raw", raw, "send raw points (60-230 MB clouds: use with --subsample-leaf-m 0.1) instead of voxels");
  app.add_flag("--l2", l2, "L2 matcher on eigen features instead of the shipped RF_eigen+shapes");
  app.add_option("--model", model_path, "RF model file");
  app.add_option("--fleet-rate", fleet_rate, "fleet level: queries/s offered in total (0: skip the level)");
  app.add_option("--fleet-vehicles", fleet_vehicles, "fleet level: vehicles, each on its own schedule")->check(CLI::Range(1, 256));
  app.add_option("--fleet-seconds", fleet_seconds, "fleet level: duration")->check(CLI::Range(1.0, 3600.0));
  CLI11_PARSE(app, argc, argv);
  io::PipelineConfig config = io::pipeline_preset("kitti-hdl64");
  std::string model;
  if (l2) {
    config.localizer.matcher.type = MatcherType::kL2;
    config.localizer.matcher.use_shapes = false;
  } else {
    std::ifstream f(model_path, std::ios::binary);
    if (!f) {
      std::fprintf(stderr, "segmatch-bench-server: cannot read %s (give --model or --l2)\n", model_path.c_str());
      return 1;
    }
    model.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  config.local_cloud.subsample_leaf_m = subsample_leaf_m;
  std::printf("matcher %s, %s queries\n", l2 ? "L2 (eigen)" : "RF_eigen+shapes", raw ? "raw" : "voxelized");
  const auto t0 = Clock::now();
  const sim::City city = sim::make_city(sim::dataset_preset("tiny", seed));
  const std::string map_path = build_map(city, config, model);
  const VoxelGridConfig& voxel = config.localizer.segmentation.voxel;
  const std::vector<api::LocalizeRequest> requests = revisit_requests(city, config.local_cloud, raw ? nullptr : &voxel, 10.0);
  size_t points = 0;
  for (const auto& r : requests) points += r.points.size();
  std::printf("set-up %.0f s: %zu revisit local clouds, %.0f points on average\n",
              std::chrono::duration<double>(Clock::now() - t0).count(), requests.size(), double(points) / requests.size());
  server::ServerConfig sc;
  sc.port = 0;
  sc.workers = workers;
  sc.log_requests = false;
  sc.stats_interval_s = 0;
  server::Server server(sc, server::load_map(map_path));
  server.start();
  std::printf("server on %s, %u cores\n", server.address().c_str(), std::thread::hardware_concurrency());
  std::printf("closed loop: each client sends its next query as soon as it has the answer\n");
  for (int clients : {1, 4, 16}) run_level(server.port(), requests, clients, std::max(1, queries_per_level / clients));
  if (fleet_rate > 0.0) {
    std::printf("open loop: a fleet querying on fixed schedules, latency from the scheduled send time\n");
    run_fleet(server.port(), requests, fleet_vehicles, fleet_rate, fleet_seconds);
  }
  server.stop();
  std::filesystem::remove(map_path);
  return 0;
}
