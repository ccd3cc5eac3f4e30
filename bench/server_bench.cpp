// segmatch-bench-server: throughput and latency of segmatch-server over loopback with 1, 4
// and 16 concurrent clients (and tracked levels: the same queries with a tracker's prior, as full requests and as
// tracking requests), on a simulated tiny city mapped by its first traversal and queried with the revisit's voxelized
// local clouds (HDL-64E, 60 m cylinder), with the shipped RF model (or --l2). Both request kinds in the same run:
// LOCALIZE (the cloud) and LOCALIZE_SEGMENTS (the vehicle's segments, made beforehand by segmatch_vehicle and timed
// apart as the client's own work). Each query encodes its request inside the timed loop.
// Closed loop (clients back to back) and open loop (a fleet on fixed schedules at an offered
// rate). Prints figures (and --json FILE), asserts nothing.
// --soak: instead, segmatch-server as its own process, 16 clients x 1000 queries (cloud and
// segments alternately), its resident memory after the first 100 and at the end
// (server_soak.h); exits 1 when the soak fails (errors, RSS growth over 5 %, unclean exit).
#include <segmatch/api/client.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/server/console.h>
#include <segmatch/server/server.h>
#include <segmatch/sim/city.h>
#include <segmatch/vehicle/segment_query.h>

#include "console_poller.h"
#include "server_bench_world.h"
#include "server_soak.h"

#include <nlohmann/json.hpp>

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <thread>

using namespace segmatch;
using Clock = std::chrono::steady_clock;

namespace {

using bench::build_map;
using bench::revisit_requests;

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(p * (v.size() - 1) + 0.5))];
}

// One request kind: how a client sends query i.
struct Kind {
  std::string name;
  std::function<api::LocalizeReply(api::Client&, size_t)> send;
  size_t count = 0;
};

struct LevelResult {
  int clients = 0;
  // server_p50_ms: frame received to reply encoded (queueing for a worker included);
  // work_p50_ms: the localizer's own time on the request (LOCALIZE_REPLY timings.total).
  double queries_per_s = 0, p50_ms = 0, p99_ms = 0, server_p50_ms = 0, work_p50_ms = 0;
  int errors = 0, localized = 0, answered = 0;
  nlohmann::json to_json() const {
    return {{"clients", clients},        {"queries_per_s", queries_per_s},
            {"p50_ms", p50_ms},          {"p99_ms", p99_ms},
            {"errors", errors},          {"localized", localized},
            {"answered", answered},      {"server_p50_ms", server_p50_ms},
            {"work_p50_ms", work_p50_ms}};
  }
};

// What the clients of one level saw: latencies of answered queries, errors, localizations.
struct Tally {
  std::mutex mutex;
  std::vector<double> latencies_ms, server_ms, work_ms, retrieve_ms, classify_ms, verify_ms, refine_ms;
  std::atomic<int> errors{0}, localized{0};

  // One query; its latency counts from `since` (the send, or the scheduled send time).
  void query(api::Client& client, const Kind& kind, size_t i, Clock::time_point since) {
    api::LocalizeReply reply;
    try {
      reply = kind.send(client, i);
    } catch (const std::exception&) {
      ++errors;
      return;
    }
    localized += reply.status == api::LocalizeStatus::kLocalized;
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - since).count();
    std::lock_guard<std::mutex> lock(mutex);
    latencies_ms.push_back(ms);
    server_ms.push_back(reply.timings.server_total);
    work_ms.push_back(reply.timings.total);
    retrieve_ms.push_back(reply.timings.retrieve), classify_ms.push_back(reply.timings.classify);
    verify_ms.push_back(reply.timings.verify), refine_ms.push_back(reply.timings.refine);
  }
  LevelResult result(int clients, double seconds) const {
    LevelResult r;
    r.clients = clients;
    r.answered = static_cast<int>(latencies_ms.size());
    r.queries_per_s = latencies_ms.size() / seconds;
    r.p50_ms = percentile(latencies_ms, 0.5), r.p99_ms = percentile(latencies_ms, 0.99);
    r.server_p50_ms = percentile(server_ms, 0.5);
    r.work_p50_ms = percentile(work_ms, 0.5);
    r.errors = errors.load(), r.localized = localized.load();
    std::printf(
        "%4d queries in %6.1f s = %6.2f queries/s, latency p50 %7.1f ms p99 %7.1f ms, server p50 %6.1f ms, "
        "work p50 %5.1f ms (retrieve %.1f classify %.1f verify %.1f refine %.1f), %d localized, %d errors\n",
        r.answered, seconds, r.queries_per_s, r.p50_ms, r.p99_ms, r.server_p50_ms, r.work_p50_ms,
        percentile(retrieve_ms, 0.5), percentile(classify_ms, 0.5), percentile(verify_ms, 0.5),
        percentile(refine_ms, 0.5), r.localized, r.errors);
    return r;
  }
};

api::Client connect(uint16_t port) {
  api::ClientOptions options;
  options.reply_timeout_s = 600;
  return api::Client("127.0.0.1", port, options);
}

// `clients` connections, each sending `per_client` queries back to back.
LevelResult run_level(uint16_t port, const Kind& kind, int clients, int per_client) {
  Tally tally;
  const auto start = Clock::now();
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] {
      api::Client client = connect(port);
      for (int i = 0; i < per_client; ++i) tally.query(client, kind, (c * 7 + i) % kind.count, Clock::now());
    });
  for (std::thread& t : threads) t.join();
  std::printf("  %2d clients: ", clients);
  return tally.result(clients, std::chrono::duration<double>(Clock::now() - start).count());
}

// A fleet: `clients` vehicles together asking `rate` queries/s, each on its own fixed schedule
// (a vehicle queries every few metres whether or not the previous answer was quick), for
// `seconds`. Latency counts from the scheduled send time, so a queue that builds up shows in
// it (no coordinated omission); a vehicle whose answer is late sends its next query at once.
LevelResult run_fleet(uint16_t port, const Kind& kind, int clients, double rate, double seconds) {
  Tally tally;
  const auto start = Clock::now() + std::chrono::milliseconds(200);
  const std::chrono::duration<double> period(clients / rate);
  const int per_client = std::max(1, static_cast<int>(seconds * rate / clients));
  std::vector<std::thread> threads;
  for (int c = 0; c < clients; ++c)
    threads.emplace_back([&, c] {
      api::Client client = connect(port);
      const auto first =
          start + std::chrono::duration_cast<Clock::duration>(period * (static_cast<double>(c) / clients));
      for (int i = 0; i < per_client; ++i) {
        const auto due = first + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(i));
        std::this_thread::sleep_until(due);
        tally.query(client, kind, (c * 7 + i) % kind.count, due);
      }
    });
  for (std::thread& t : threads) t.join();
  std::printf("  %2d vehicles at %.1f queries/s offered: ", clients, rate);
  return tally.result(clients, std::chrono::duration<double>(Clock::now() - start).count());
}

// The vehicle's own work, apart: every cloud segmented as a car would, with the map's
// parameters (INFO), timed per query on this thread.
std::vector<api::LocalizeSegmentsRequest> segment_like_a_vehicle(uint16_t port,
                                                                 const std::vector<api::LocalizeRequest>& requests,
                                                                 std::vector<double>& client_ms) {
  const vehicle::SegmentQuery vehicle_side = vehicle::SegmentQuery::from_info(connect(port).info());
  std::vector<api::LocalizeSegmentsRequest> out;
  std::vector<double> segments, points;
  for (const api::LocalizeRequest& r : requests) {
    ModuleTimings t;
    out.push_back(vehicle_side.make_request(r, &t));
    client_ms.push_back(t.total_ms);
    segments.push_back(static_cast<double>(out.back().segments.size()));
    double n = 0;
    for (const Segment& s : out.back().segments) n += static_cast<double>(s.points.size());
    points.push_back(n);
  }
  std::printf(
      "vehicle side (segmentation and description, one thread): median %.1f ms per query; %.0f segments and "
      "%.0f of their points sent per query (medians)\n",
      percentile(client_ms, 0.5), percentile(segments, 0.5), percentile(points, 0.5));
  return out;
}

template <typename Request>
double median_bytes(const std::vector<Request>& requests) {
  std::vector<double> bytes;
  for (const Request& r : requests) bytes.push_back(static_cast<double>(api::encode(r).size()));
  return percentile(bytes, 0.5);
}

struct BenchOptions {
  int queries_per_level = 32, fleet_vehicles = 16;
  double fleet_rate = 20.0, fleet_seconds = 30.0;
};

nlohmann::json run_kind(uint16_t port, const Kind& kind, double request_bytes_median, const BenchOptions& o,
                        std::initializer_list<int> levels = {1, 4, 16}, bool fleet = true) {
  std::printf("%s: median request %.0f bytes\n", kind.name.c_str(), request_bytes_median);
  nlohmann::json j = {{"request_bytes_median", request_bytes_median}, {"closed_loop", nlohmann::json::array()}};
  for (int clients : levels)
    j["closed_loop"].push_back(run_level(port, kind, clients, std::max(1, o.queries_per_level / clients)).to_json());
  if (fleet && o.fleet_rate > 0.0) {
    const LevelResult f = run_fleet(port, kind, o.fleet_vehicles, o.fleet_rate, o.fleet_seconds);
    j["open_loop"] = f.to_json();
    j["open_loop"]["offered_queries_per_s"] = o.fleet_rate;
  }
  return j;
}

// The command line: what to set up and which levels to run.
struct Options {
  int workers = 0;
  BenchOptions bench;
  uint64_t seed = 3;
  double subsample_leaf_m = 0.0;
  bool raw = false, l2 = false, soak = false, console_poll = false;
  int console_rounds = 3, console_clients = 4;
  std::string model_path = SEGMATCH_SOURCE_DIR "/maps/models/default-rf.yml", json_path, map_points = "lazy";
  bench::SoakConfig soak_config;
};

void add_options(CLI::App& app, Options& o) {
  app.add_option("--workers", o.workers, "server localization threads (0 = cores)");
  app.add_option("--queries", o.bench.queries_per_level,
                 "queries per level, spread over its clients (at least one each)");
  app.add_option("--seed", o.seed, "city seed");
  app.add_option("--subsample-leaf-m", o.subsample_leaf_m, "per-scan subsampling of the local cloud (0 = full scans)");
  app.add_flag("--raw", o.raw, "send raw points (60-230 MB clouds: use with --subsample-leaf-m 0.1) instead of voxels");
  app.add_flag("--l2", o.l2, "L2 matcher on eigen features instead of the shipped RF_eigen+shapes");
  app.add_option("--model", o.model_path, "RF model file");
  app.add_option("--fleet-rate", o.bench.fleet_rate, "fleet level: queries/s offered in total (0: skip the level)");
  app.add_option("--fleet-vehicles", o.bench.fleet_vehicles, "fleet level: vehicles, each on its own schedule")
      ->check(CLI::Range(1, 256));
  app.add_option("--fleet-seconds", o.bench.fleet_seconds, "fleet level: duration")->check(CLI::Range(1.0, 3600.0));
  app.add_option("--map-points", o.map_points, "the server's map points: lazy (read on demand) or memory")
      ->capture_default_str()
      ->check(CLI::IsMember({"lazy", "memory"}));
  app.add_flag("--soak", o.soak, "soak run: segmatch-server as its own process, clients x queries, its RSS watched");
  app.add_option("--soak-clients", o.soak_config.clients, "soak: concurrent clients")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--soak-queries", o.soak_config.queries_per_client, "soak: queries per client")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--server-binary", o.soak_config.server_binary,
                 "soak: segmatch-server to run (default: next to this program)");
  app.add_flag("--console-poll", o.console_poll,
               "instead: closed-loop cloud queries with and without a browser's polling of the operator's page (each "
               "second), alternately, and the ratio of the median queries/s");
  app.add_option("--console-rounds", o.console_rounds, "--console-poll: runs of each kind")
      ->capture_default_str()
      ->check(CLI::Range(1, 50));
  app.add_option("--console-clients", o.console_clients, "--console-poll: concurrent clients")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--json", o.json_path, "write the figures as JSON: {\"cloud\": {...}, \"segments\": {...}}");
}

// The soak run: segmatch-server as its own process, cloud and segments requests alternately,
// each client through the revisit in its own order. Exit code 0 if it passed.
int soak(Options o, const std::string& map_path, const std::vector<api::LocalizeRequest>& requests,
         const std::vector<api::LocalizeSegmentsRequest>& segment_requests) {
  bench::SoakConfig& config = o.soak_config;
  if (config.server_binary.empty())
    config.server_binary = (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "segmatch-server").string();
  config.map_path = map_path;
  config.workers = o.workers;
  const bench::SoakResult r = bench::run_soak(config, [&](api::Client& c, size_t client, size_t i) {
    const size_t q = client * 7 + i / 2;
    return i % 2 == 0 ? c.localize(requests[q % requests.size()])
                      : c.localize_segments(segment_requests[q % segment_requests.size()]);
  });
  std::filesystem::remove(map_path);
  if (!o.json_path.empty()) std::ofstream(o.json_path) << nlohmann::json{{"soak", r.to_json()}}.dump(2) << "\n";
  return r.passed(config) ? 0 : 1;
}

// --console-poll: the page served beside this server, polled or not (console_poller.h).
int console_poll(const server::Server& server, const Kind& kind, const Options& o) {
  const server::Console console({}, server);
  const int per_client = std::max(1, o.bench.queries_per_level / o.console_clients);
  std::printf("console on %s; %d clients x %d queries per run, %d runs of each\n", console.url().c_str(),
              o.console_clients, per_client, o.console_rounds);
  return bench::compare_console_poll(console.port(), o.console_rounds, o.json_path, [&] {
    return run_level(server.port(), kind, o.console_clients, per_client).queries_per_s;
  });
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"segmatch-bench-server: loopback throughput and latency of segmatch-server, cloud and segments queries"};
  Options o;
  add_options(app, o);
  CLI11_PARSE(app, argc, argv);
  io::PipelineConfig config = io::pipeline_preset("kitti-hdl64");
  std::string model;
  if (o.l2) {
    config.localizer.matcher.type = MatcherType::kL2;
    config.localizer.matcher.use_shapes = false;
  } else {
    std::ifstream f(o.model_path, std::ios::binary);
    if (!f) {
      std::fprintf(stderr, "segmatch-bench-server: cannot read %s (give --model or --l2)\n", o.model_path.c_str());
      return 1;
    }
    model.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  }
  config.local_cloud.subsample_leaf_m = o.subsample_leaf_m;
  std::printf("matcher %s, %s queries\n", o.l2 ? "L2 (eigen)" : "RF_eigen+shapes", o.raw ? "raw" : "voxelized");
  const auto t0 = Clock::now();
  const sim::City city = sim::make_city(sim::dataset_preset("tiny", o.seed));
  const std::string map_path = build_map(city, config, model);
  const VoxelGridConfig& voxel = config.localizer.segmentation.voxel;
  const std::vector<api::LocalizeRequest> requests =
      revisit_requests(city, config.local_cloud, o.raw ? nullptr : &voxel, 10.0);
  size_t points = 0;
  for (const auto& r : requests) points += r.points.size();
  std::printf("set-up %.0f s: %zu revisit local clouds (from drifting simulated odometry), %.0f points on average\n",
              std::chrono::duration<double>(Clock::now() - t0).count(), requests.size(),
              double(points) / requests.size());
  server::ServerConfig sc;
  sc.port = 0;
  sc.workers = o.workers;
  sc.log_requests = false;
  sc.stats_interval_s = 0;
  server::MapLoadOptions load;
  load.points = o.map_points == "lazy" ? server::MapPoints::kLazy : server::MapPoints::kMemory;
  server::Server server(sc, server::load_map(map_path, load));
  std::printf("map points: %s\n", o.map_points.c_str());
  server.start();
  std::printf("server on %s, %u cores\n", server.address().c_str(), std::thread::hardware_concurrency());
  if (o.console_poll) {
    const Kind cloud{"cloud (LOCALIZE)", [&](api::Client& c, size_t i) { return c.localize(requests[i]); },
                     requests.size()};
    const int rc = console_poll(server, cloud, o);
    server.stop();
    std::filesystem::remove(map_path);
    return rc;
  }

  std::vector<double> client_ms;
  const std::vector<api::LocalizeSegmentsRequest> segment_requests =
      segment_like_a_vehicle(server.port(), requests, client_ms);
  const double client_ms_median = percentile(client_ms, 0.5);
  if (o.soak) {
    server.stop();
    return soak(o, map_path, requests, segment_requests);
  }

  std::printf("closed loop: each client sends its next query as soon as it has the answer\n");
  const Kind cloud{"cloud (LOCALIZE)", [&](api::Client& c, size_t i) { return c.localize(requests[i]); },
                   requests.size()};
  const Kind segments{"segments (LOCALIZE_SEGMENTS)",
                      [&](api::Client& c, size_t i) { return c.localize_segments(segment_requests[i]); },
                      segment_requests.size()};
  nlohmann::json out;
  out["cloud"] = run_kind(server.port(), cloud, median_bytes(requests), o.bench);
  out["segments"] = run_kind(server.port(), segments, median_bytes(segment_requests), o.bench);
  out["segments"]["client_segmenting_ms_median"] = client_ms_median;
  // The tracked level: each query with a tracker's prior (the truth, radius 3 m: api::Tracker's
  // least), answered by registration around it (registration.h). No newest scans: the simulated
  // local clouds come whole.
  std::vector<api::LocalizeRequest> tracked = requests;
  for (api::LocalizeRequest& r : tracked) r.flags |= api::kFlagHasPrior, r.prior_radius_m = 3.0;
  std::vector<double> tracked_client_ms;
  const std::vector<api::LocalizeSegmentsRequest> tracked_segments =
      segment_like_a_vehicle(server.port(), tracked, tracked_client_ms);
  const Kind tracked_cloud{"tracked cloud (LOCALIZE, 3 m prior)",
                           [&](api::Client& c, size_t i) { return c.localize(tracked[i]); }, tracked.size()};
  const Kind tracked_segs{"tracked segments (LOCALIZE_SEGMENTS, 3 m prior)",
                          [&](api::Client& c, size_t i) { return c.localize_segments(tracked_segments[i]); },
                          tracked_segments.size()};
  out["tracked_cloud"] = run_kind(server.port(), tracked_cloud, median_bytes(tracked), o.bench, {1, 4}, false);
  out["tracked_segments"] =
      run_kind(server.port(), tracked_segs, median_bytes(tracked_segments), o.bench, {1, 4}, false);
  // Tracking on the surface layer (protocol revision 11): the same queries as tracking requests,
  // the segments within track.window_m without points and at most track.max_points of the
  // newest scans (the last 10 m of kept scans, placed by the drifting odometry).
  const vehicle::SegmentQuery vehicle_side = vehicle::SegmentQuery::from_info(connect(server.port()).info());
  std::vector<api::LocalizeSegmentsRequest> tracking;
  for (size_t i = 0; i < tracked_segments.size(); ++i) {
    api::LocalizeSegmentsRequest full = tracked_segments[i];
    full.flags |= api::kSegmentsFlagNewestScans | api::kSegmentsFlagRefusalCode | api::kSegmentsFlagDetail;
    full.newest_points = tracked[i].newest_points;
    tracking.push_back(vehicle_side.tracking_request(full));
  }
  const Kind tracking_kind{"tracking requests (LOCALIZE_SEGMENTS bit 5, 3 m prior)",
                           [&](api::Client& c, size_t i) { return c.localize_segments(tracking[i]); }, tracking.size()};
  out["tracking_requests"] = run_kind(server.port(), tracking_kind, median_bytes(tracking), o.bench, {1, 4}, false);
  out["setup"] = {{"queries", requests.size()},
                  {"points_mean", double(points) / requests.size()},
                  {"cores", std::thread::hardware_concurrency()},
                  {"matcher", o.l2 ? "L2" : "RF_eigen+shapes"}};
  server.stop();
  std::filesystem::remove(map_path);
  if (!o.json_path.empty()) {
    std::ofstream f(o.json_path);
    f << out.dump(2) << "\n";
    if (!f) {
      std::fprintf(stderr, "segmatch-bench-server: cannot write %s\n", o.json_path.c_str());
      return 1;
    }
  }
  return 0;
}
