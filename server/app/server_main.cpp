// segmatch-server: serves one segment map to many vehicles over the SGMQ protocol.
#include <segmatch/server/console.h>
#include <segmatch/server/log.h>
#include <segmatch/server/metrics.h>
#include <segmatch/server/server.h>

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>

#include <sys/stat.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

using namespace segmatch;

namespace {

// The token comes from a file so it never shows in `ps` or shell history. Trailing
// whitespace (the newline an editor adds) is not part of it.
std::string read_token(const std::string& path) {
  const std::string token = cli::read_token_file(path);
  if (token.empty()) throw std::runtime_error("token file " + path + " is empty");
  struct stat st {};
  // Group access is how service managers hand secrets over (a Kubernetes secret with fsGroup,
  // systemd credentials); access for everyone is a mistake.
  if (::stat(path.c_str(), &st) == 0 && (st.st_mode & 007))
    server::log_to_stderr(server::LogLevel::kWarning,
                          "token file " + path + " is readable by every user (chmod 600 it)");
  return token;
}

// Blocks SIGINT/SIGTERM/SIGHUP in every thread (they inherit the mask) so that only sigwait()
// in main sees them; SIGPIPE is ignored (sends use MSG_NOSIGNAL anyway).
sigset_t block_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  std::signal(SIGPIPE, SIG_IGN);
  return set;
}

void info(const std::string& text) { server::log_to_stderr(server::LogLevel::kInfo, text); }

std::string describe(const server::LoadedMap& map, const std::string& points, double load_s) {
  std::ostringstream s;
  s << "map '" << map.metadata.name << "': " << map.segment_count() << " segments, matcher "
    << (map.config.localizer.matcher.type == MatcherType::kL2 ? "l2" : "random_forest") << ", local cloud radius "
    << map.config.local_cloud.radius_m << " m, points " << points << ", ready in " << load_s << " s";
  return s.str();
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// SIGHUP: the map file is opened and checked whole before it replaces the served one; on any
// failure the old map keeps serving. Replace the file by renaming a new one over it (as
// segmatch-mapbuilder writes maps): the old map's lazy point reads keep the old file open.
void reload(server::Server& served, const std::string& path, const server::MapLoadOptions& load,
            const std::string& points) {
  info("SIGHUP: reloading " + path + " ...");
  const auto t0 = std::chrono::steady_clock::now();
  try {
    std::shared_ptr<const server::LoadedMap> map = server::load_map(path, load);
    for (const std::string& w : map->warnings) server::log_to_stderr(server::LogLevel::kWarning, w);
    const std::string what = describe(*map, points, seconds_since(t0));
    served.replace_map(std::move(map));
    info("reloaded: " + what);
  } catch (const std::exception& e) {
    server::log_to_stderr(server::LogLevel::kError,
                          "reload failed, still serving map '" + served.map()->metadata.name + "': " + e.what());
  }
}

// --http-port: the operator's page (console.h) on the server's token and metrics; null without.
std::unique_ptr<server::Console> start_console(int http_port, server::ConsoleConfig console,
                                               const server::ServerConfig& config, const server::Server& served) {
  if (http_port < 0) return nullptr;
  console.port = static_cast<uint16_t>(http_port);
  console.token = config.token;
  console.metrics = config.metrics;
  auto page = std::make_unique<server::Console>(console, served);
  info("operator's page on " + page->url() + (config.token.empty() ? "" : "?token=... (the token file's)") +
       ", metrics at " + page->url() + "metrics");
  std::cout << "console on " << page->url() << std::endl;
  return page;
}

// Every option of the command line.
struct ServerOptions {
  std::string map_path, token_file;
  server::ServerConfig config;
  double max_frame_mb = 64.0;
  int metrics_port = -1;
  std::string metrics_listen = "127.0.0.1";
  int http_port = -1;
  server::ConsoleConfig console;
  std::string log_requests = "on";  // on|off rather than a flag: a service file says which
  std::string map_points = "lazy";
  double point_cache_mb = 32.0;
};

void add_options(CLI::App& app, ServerOptions& o) {
  app.add_option("--map", o.map_path, "segment map (.sqlite) built by segmatch-mapbuilder")->required();
  app.add_option("--listen", o.config.listen_address, "address to listen on (default loopback)")->capture_default_str();
  app.add_option("--port", o.config.port, "TCP port; 0 = ephemeral (the chosen port is printed)")
      ->capture_default_str();
  app.add_option("--workers", o.config.workers, "localization threads (default: number of cores)");
  app.add_option("--token-file", o.token_file, "file holding the shared-secret token clients must send first");
  app.add_option("--max-frame-mb", o.max_frame_mb, "largest accepted frame payload (MiB)")
      ->capture_default_str()
      ->check(CLI::Range(0.001, 4095.0));
  app.add_option("--read-timeout-s", o.config.read_timeout_s, "drop a connection idle or stalled this long")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--request-timeout-s", o.config.request_timeout_s,
                 "answer ERROR REQUEST_TIMEOUT to a localization not done this long after it arrived, and free its "
                 "worker (0 = no limit)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--max-connections", o.config.max_connections, "connections served at once")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--metrics-port", o.metrics_port,
                 "serve Prometheus metrics over HTTP on this port (GET /metrics; 0: a free port, printed)")
      ->check(CLI::Range(0, 65535));
  app.add_option("--metrics-listen", o.metrics_listen, "address of the metrics endpoint (default loopback)")
      ->capture_default_str();
  app.add_option("--http-port", o.http_port,
                 "serve the operator's page and its JSON API (docs/console.md) over HTTP on this port, with the "
                 "token if there is one, and GET /metrics (0: a free port, printed); may equal --metrics-port")
      ->check(CLI::Range(0, 65535));
  app.add_option("--http-listen", o.console.listen_address, "address of the operator's page (default loopback)")
      ->capture_default_str();
  app.add_option("--http-threads", o.console.threads, "HTTP threads of the operator's page")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--log-requests", o.log_requests, "one log line per request: on or off")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--stats-interval-s", o.config.stats_interval_s, "counters line period (0 = none)")
      ->capture_default_str();
  app.add_option("--map-points", o.map_points,
                 "lazy: segment points stay in the map file, read when a query refines against them (a bounded "
                 "cache); memory: all loaded at start")
      ->capture_default_str()
      ->check(CLI::IsMember({"lazy", "memory"}));
  app.add_option("--point-cache-mb", o.point_cache_mb, "with --map-points lazy: points kept cached (MiB)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1e6));
}

// Loads the map, serves it until SIGINT or SIGTERM (SIGHUP reloads it), and reports what was served.
int serve(ServerOptions& o, const server::MapLoadOptions& load) {
  server::ServerConfig& config = o.config;
  const sigset_t signals = block_signals();
  if (!o.token_file.empty()) config.token = read_token(o.token_file);
  info("loading " + o.map_path + " ...");
  const auto load_start = std::chrono::steady_clock::now();
  std::shared_ptr<const server::LoadedMap> map = server::load_map(o.map_path, load);
  const double load_s = seconds_since(load_start);
  for (const std::string& w : map->warnings) server::log_to_stderr(server::LogLevel::kWarning, w);
  info(describe(*map, o.map_points, load_s) + (config.token.empty() ? "" : ", token required"));
  // The page's port carries /metrics too: the same port given twice is one listener.
  const bool shared_port = o.http_port > 0 && o.metrics_port == o.http_port;
  if (o.metrics_port >= 0 && !shared_port) {
    config.metrics = std::make_shared<server::Metrics>(o.metrics_listen, static_cast<uint16_t>(o.metrics_port));
    info("metrics on http://" + o.metrics_listen + ":" + std::to_string(config.metrics->port()) + "/metrics");
  } else if (o.http_port >= 0) {
    config.metrics = std::make_shared<server::Metrics>();
  }
  server::Server server(config, map);
  server.start();
  std::cout << "listening on " << server.address() << std::endl;
  std::unique_ptr<server::Console> page =
      start_console(o.http_port, o.console, config, server);  // reset before the server stops
  int signal = 0;
  while (sigwait(&signals, &signal) == 0 && signal == SIGHUP) reload(server, o.map_path, load, o.map_points);
  info("signal " + std::to_string(signal) + ": stopping (finishing in-flight requests)");
  page.reset();
  server.stop();
  const server::ServerCounters c = server.counters();
  info("stopped: " + std::to_string(c.requests) + " requests, " + std::to_string(c.localized) + " localized, " +
       std::to_string(c.errors) + " errors");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"segmatch-server: localization against a segment map over TCP (docs/protocol.md)"};
  ServerOptions o;
  add_options(app, o);
  cli::add_version_flag(app, "segmatch-server");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  o.config.log_requests = o.log_requests == "on";
  server::MapLoadOptions load;
  load.points = o.map_points == "lazy" ? server::MapPoints::kLazy : server::MapPoints::kMemory;
  load.cache_points = static_cast<size_t>(o.point_cache_mb * 1024 * 1024 / sizeof(Point));
  o.config.max_frame_bytes = static_cast<size_t>(o.max_frame_mb * 1024 * 1024);
  try {
    return serve(o, load);
  } catch (const std::exception& e) {
    server::log_to_stderr(server::LogLevel::kError, std::string("segmatch-server: ") + e.what());
    return 1;
  }
}
