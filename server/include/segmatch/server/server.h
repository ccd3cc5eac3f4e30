// The TCP localization server (protocol in docs/protocol.md).
//
// Threads: one accept thread; one thread per connection (at most max_connections, further
// connections get ERROR kServerBusy and are closed) that reads frames with poll()-bounded
// timeouts, answers PING / INFO / HELLO itself and hands each LOCALIZE to a bounded pool of
// `workers` localization threads, waiting for the result. A slow or dead client therefore
// only ever holds its own connection thread: it is dropped after read_timeout_s without a
// byte, and it never occupies a localization worker while it trickles a frame in (frames are
// read whole before they are queued). Each connection has at most one request in flight, so
// the queue is bounded by max_connections. A request that runs past request_timeout_s is
// stopped by its worker and answered with ERROR REQUEST_TIMEOUT.
//
// stop(): the accept thread stops, idle connections close, every request already received is
// localized and answered, then all threads are joined.
#pragma once

#include <segmatch/server/map_service.h>
#include <segmatch/server/recent.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

namespace segmatch {
namespace server {

class Metrics;

struct ServerConfig {
  std::string listen_address = "127.0.0.1";  // loopback unless another address is asked for
  uint16_t port = 7878;                      // 0: ephemeral, see Server::port()
  int workers = 0;                           // localization threads; 0 = hardware cores
  std::string token;                         // shared secret; empty = no authentication
  size_t max_frame_bytes = 64u << 20;        // payload limit; larger frames: ERROR, close
  double read_timeout_s = 10.0;              // idle connection / frame-in-progress limit
  double write_timeout_s = 10.0;             // a client that does not read its reply is dropped
  // A LOCALIZE / LOCALIZE_SEGMENTS not answered this long after it was read (queueing for a
  // worker included) gets ERROR REQUEST_TIMEOUT, and its worker stops (between the localizer's
  // stages, core/deadline.h) and takes the next request. <= 0: no limit.
  double request_timeout_s = 30.0;
  int max_connections = 64;
  double stats_interval_s = 10.0;  // periodic counters line; <= 0 = none
  bool log_requests = true;        // one line per request
  // Where log lines go (one call per line, without newline); default: stderr, each line with a
  // timestamp and a level (log.h).
  std::function<void(const std::string&)> log;
  // Prometheus metrics (metrics.h), counted as frames are answered; null: none.
  std::shared_ptr<Metrics> metrics;
  // The recent answers kept for the operator's page (recent.h, docs/console.md).
  size_t recent_answers = 4096;
};

struct ServerCounters {
  uint64_t frames_received = 0;  // frames read whole (answered or still in work)
  uint64_t requests = 0;         // frames answered (any type)
  uint64_t localize_requests = 0;
  uint64_t localized = 0;
  uint64_t errors = 0;               // ERROR replies sent
  uint64_t timed_out = 0;            // of which REQUEST_TIMEOUT (request_timeout_s)
  uint64_t connections = 0;          // accepted and served
  uint64_t refused_connections = 0;  // over max_connections
};

class Server {
 public:
  Server(const ServerConfig& config, std::shared_ptr<const LoadedMap> map);
  ~Server();  // stop()
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // Binds, listens and starts the threads. Throws std::runtime_error (address in use, bad
  // address, ...).
  void start();
  uint16_t port() const;        // the bound port (after start)
  std::string address() const;  // "ADDR:PORT"
  // Graceful stop as described above; idempotent, thread-safe. Returns when all threads ended.
  void stop();
  ServerCounters counters() const;
  // Serves `map` from the next request on (a reload: SIGHUP in segmatch-server). Requests
  // already running finish on the map they started with, which lives until the last of them
  // ends. Thread-safe. Throws std::invalid_argument for a null map.
  void replace_map(std::shared_ptr<const LoadedMap> map);
  std::shared_ptr<const LoadedMap> map() const;  // the map new requests get
  // The last answers and the localization statistics (the operator's page reads them).
  const Recent& recent() const;

  struct State;

 private:
  std::unique_ptr<State> state_;
};

}  // namespace server
}  // namespace segmatch
