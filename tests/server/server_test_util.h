// The server suites' shared world (server_world.h) and a server on a loopback port.
#pragma once

#include "segmatch/api/client.h"
#include "segmatch/server/server.h"
#include "server/server_world.h"
#include "support/fixture_cache.h"
#include "support/run_command.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <mutex>

namespace segmatch::testing {

struct TestWorld {
  std::string folder;    // this process's scratch folder
  std::string map_path;  // the shared world's map: read it, copy it, never write it
  io::PipelineConfig config;
  std::string queries_path;
  // The revisit local clouds every 15 m, read on first use (~300 MB: most processes need only
  // the map).
  const std::vector<Query>& queries() const {
    std::call_once(queries_once_, [this] {
      queries_ = read_queries(queries_path);
      std::printf("[server] %zu revisit queries from %s\n", queries_.size(), queries_path.c_str());
    });
    return queries_;
  }
  // The folder goes with the test process unless SEGMATCH_KEEP_TEST_FILES is set (to read the
  // logs of the processes a test ran).
  ~TestWorld() {
    std::error_code ec;
    if (!folder.empty() && !std::getenv("SEGMATCH_KEEP_TEST_FILES")) std::filesystem::remove_all(folder, ec);
  }

 private:
  mutable std::once_flag queries_once_;
  mutable std::vector<Query> queries_;
};

// Built once per build by make_server_world (under the fixture lock, so the server suites and
// Deploy running side by side wait for one build) and loaded once per process.
inline const TestWorld& test_world() {
  static std::once_flag once;
  static std::unique_ptr<TestWorld> world;
  std::call_once(once, [] {
    world = std::make_unique<TestWorld>();
    world->folder =
        (std::filesystem::temp_directory_path() / ("segmatch_server_test_" + std::to_string(::getpid()))).string();
    std::filesystem::create_directories(world->folder);
    // $SEGMATCH_SERVER_WORLD_TOOL: another build's make_server_world. The sanitizer suites use the
    // optimised build's: the world is their input, not code under test, and slow to build under ASan.
    const char* other_tool = std::getenv("SEGMATCH_SERVER_WORLD_TOOL");
    const std::filesystem::path tool =
        other_tool ? std::filesystem::path(other_tool) : test::fixture_root().parent_path() / "make_server_world";
    const std::filesystem::path cached =
        test::cached_fixture("server-world", {tool}, [&](const std::filesystem::path& dir) {
          const test::CommandResult r = test::run_command(tool.string() + " " + dir.string());
          std::printf("%s", r.output.c_str());
          if (r.code != 0) throw std::runtime_error("make_server_world failed: " + r.output);
        });
    world->map_path = (cached / "tiny.sqlite").string();
    world->config = fast_config();
    world->queries_path = (cached / "queries.bin").string();
    std::printf("[server] map %s\n", world->map_path.c_str());
  });
  return *world;
}

inline double position_error_m(const Pose3d& a, const Pose3d& b) { return (a.translation() - b.translation()).norm(); }
inline double angle_error_deg(const Pose3d& a, const Pose3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
}

// A server on an ephemeral loopback port, log lines kept for inspection; on the shared world's
// map unless given another.
struct RunningServer {
  explicit RunningServer(server::ServerConfig config = {}, std::shared_ptr<const server::LoadedMap> map = nullptr) {
    config.listen_address = "127.0.0.1";
    config.port = 0;
    if (config.workers == 0) config.workers = 2;
    config.log = [this](const std::string& line) {
      std::lock_guard<std::mutex> lock(log_mutex);
      log.push_back(line);
    };
    if (!map) {
      static const std::shared_ptr<const server::LoadedMap> shared = server::load_map(test_world().map_path);
      map = shared;
    }
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
