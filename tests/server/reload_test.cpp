// Map reload and log lines: Server::replace_map in process, and SIGHUP on
// segmatch-server as its own process with a good and a damaged new file.
#include "server_test_util.h"

#include <segmatch/server/log.h>
#include <segmatch/storage/map_reader.h>

#include <signal.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <future>
#include <regex>
#include <sstream>
#include <thread>

using namespace segmatch;
using namespace segmatch::testing;
using Ms = std::chrono::milliseconds;

namespace {

// The world map's first `count` segments, under another name.
std::string write_smaller_map(const std::string& path, const std::string& name, size_t count) {
  Segments segments = storage::MapReader::open(test_world().map_path).load_segments();
  segments.resize(std::min(count, segments.size()));
  storage::MapMetadata meta;
  meta.name = name;
  meta.parameters_json = io::to_json(test_world().config);
  storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
  writer.add_segments(segments, {});
  writer.commit();
  return path;
}

// A dense forest of identical poles: keeps the only worker busy for a while.
api::LocalizeRequest busy_work() {
  api::LocalizeRequest r;
  r.request_id = 99;
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j)
      for (float z = 0.f; z < 3.f; z += 0.04f)
        for (int k = 0; k < 16; ++k) {
          const float a = 2.f * static_cast<float>(M_PI) * static_cast<float>(k) / 16.f;
          r.points.push_back(
              Point{-30.f + 3.f * i + 0.15f * std::cos(a), -30.f + 3.f * j + 0.15f * std::sin(a), z, 0.f});
        }
  return r;
}

void wait_for_frames(const server::Server& s, uint64_t count) {
  for (int i = 0; i < 4000 && s.counters().frames_received < count; ++i) std::this_thread::sleep_for(Ms(5));
  ASSERT_GE(s.counters().frames_received, count) << "the request never arrived";
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Waits until `path` contains `text` (at most `seconds`).
bool wait_for_text(const std::string& path, const std::string& text, double seconds = 60) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < until) {
    if (read_file(path).find(text) != std::string::npos) return true;
    std::this_thread::sleep_for(Ms(20));
  }
  return false;
}

}  // namespace

// A request that arrived before the reload is answered with the old map, even though it only
// reaches the (single, busy) worker after it; INFO and later requests see the new map.
TEST(ServerRobustness, ReplaceMapKeepsRequestsInFlightOnTheOldMap) {
  server::ServerConfig config;
  config.workers = 1;
  RunningServer s(config);
  const api::LocalizeRequest query = test_world().queries().front().request;
  api::Client c0 = s.client(), c1 = s.client();
  const api::LocalizeReply before = c1.localize(query);
  ASSERT_EQ(before.status, api::LocalizeStatus::kLocalized) << before.reason;

  std::future<api::LocalizeReply> busy = std::async(std::launch::async, [&] { return c0.localize(busy_work()); });
  wait_for_frames(*s.server, 2);
  std::future<api::LocalizeReply> queued = std::async(std::launch::async, [&] { return c1.localize(query); });
  wait_for_frames(*s.server, 3);
  const std::string smaller = write_smaller_map(test_world().folder + "/reloaded.sqlite", "reloaded", 5);
  s.server->replace_map(server::load_map(smaller));
  const api::LocalizeReply answered = queued.get();
  EXPECT_EQ(answered.status, api::LocalizeStatus::kLocalized) << answered.reason;
  EXPECT_TRUE(answered.T_map_local.isApprox(before.T_map_local, 1e-9));
  busy.get();

  EXPECT_EQ(c1.info().map_name, "reloaded");
  EXPECT_EQ(c1.info().segment_count, 5u);
  const api::LocalizeReply after = c1.localize(query);
  EXPECT_NE(after.status, api::LocalizeStatus::kLocalized) << "5 segments cannot localize it";
  EXPECT_THROW(s.server->replace_map(nullptr), std::invalid_argument);
}

// segmatch-server as an operator runs it: SIGHUP after a new map was renamed over the file
// switches maps; SIGHUP after a damaged file was renamed over it keeps the map it has, says why,
// and serving goes on. Its log lines carry a timestamp and a level.
TEST(ServerRobustness, SighupReloadsTheMapFileOrKeepsTheOldOne) {
  const std::string dir = test_world().folder + "/sighup";
  std::filesystem::create_directories(dir);
  const std::string map = dir + "/map.sqlite";
  std::filesystem::copy_file(test_world().map_path, map, std::filesystem::copy_options::overwrite_existing);
  const std::string binary = std::string(SEGMATCH_BIN_DIR) + "/segmatch-server";
  ASSERT_TRUE(std::filesystem::exists(binary)) << binary << " is not built";
  const std::string command = binary + " --map " + map + " --port 0 --stats-interval-s 0 --log-requests off > " + dir +
                              "/out 2> " + dir + "/log & echo $! > " + dir + "/pid";
  ASSERT_EQ(std::system(command.c_str()), 0);
  ASSERT_TRUE(wait_for_text(dir + "/out", "\n")) << read_file(dir + "/log");
  const pid_t pid = static_cast<pid_t>(std::stol(read_file(dir + "/pid")));
  const std::string out = read_file(dir + "/out");
  const uint16_t port = static_cast<uint16_t>(std::stoi(out.substr(out.rfind(':') + 1)));
  api::Client client("127.0.0.1", port);
  EXPECT_EQ(client.info().map_name, "tiny-3");

  write_smaller_map(dir + "/new.sqlite", "reloaded", 5);
  std::filesystem::rename(dir + "/new.sqlite", map);
  ASSERT_EQ(::kill(pid, SIGHUP), 0);
  ASSERT_TRUE(wait_for_text(dir + "/log", "reloaded: map 'reloaded': 5 segments")) << read_file(dir + "/log");
  EXPECT_EQ(client.info().map_name, "reloaded");

  std::ofstream(dir + "/damaged.sqlite") << "this is not a map";
  std::filesystem::rename(dir + "/damaged.sqlite", map);
  ASSERT_EQ(::kill(pid, SIGHUP), 0);
  ASSERT_TRUE(wait_for_text(dir + "/log", "reload failed, still serving map 'reloaded': ")) << read_file(dir + "/log");
  EXPECT_EQ(client.info().map_name, "reloaded");
  EXPECT_EQ(client.localize(test_world().queries().front().request).request_id,
            test_world().queries().front().request.request_id);

  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  EXPECT_TRUE(wait_for_text(dir + "/log", "stopped: ")) << read_file(dir + "/log");
  // Every line: an ISO-8601 UTC timestamp and a level; no per-request lines (--log-requests off).
  std::istringstream log(read_file(dir + "/log"));
  const std::regex stamped(R"(^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z (INFO|WARN|ERROR) .+)");
  int lines = 0;
  for (std::string line; std::getline(log, line); ++lines) {
    EXPECT_TRUE(std::regex_match(line, stamped)) << line;
    EXPECT_EQ(line.find("LOCALIZE"), std::string::npos) << line;
  }
  EXPECT_GE(lines, 6);
}

TEST(ServerLog, LinesStartWithAnIsoUtcTimestampAndALevel) {
  const std::chrono::system_clock::time_point when{
      std::chrono::milliseconds(946684799999)};  // the last millisecond of 1999
  EXPECT_EQ(server::format_log_line(server::LogLevel::kInfo, "ready", when), "1999-12-31T23:59:59.999Z INFO ready");
  EXPECT_EQ(server::format_log_line(server::LogLevel::kWarning, "x", when), "1999-12-31T23:59:59.999Z WARN x");
  EXPECT_EQ(server::format_log_line(server::LogLevel::kError, "y", std::chrono::system_clock::time_point{}),
            "1970-01-01T00:00:00.000Z ERROR y");
}
