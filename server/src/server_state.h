// Internals of Server shared by server.cpp (accept loop, stop, counters) and connection.cpp.
#pragma once

#include "segmatch/server/log.h"
#include "segmatch/server/server.h"
#include "worker_pool.h"

#include <segmatch/api/socket_io.h>

#include <atomic>
#include <condition_variable>
#include <list>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace segmatch {
namespace server {

// Counters and the latencies of the LOCALIZE requests of the current stats period.
class Stats {
 public:
  void record(bool is_localize, bool localized, bool error, bool timed_out, double latency_ms);
  void received();
  void connection(bool refused);
  ServerCounters counters() const;
  // "stats: ..." for the period since the last call, then starts a new period.
  std::string period_line();

 private:
  mutable std::mutex mutex_;
  ServerCounters counters_;
  std::vector<double> period_latencies_ms_;
  uint64_t period_requests_ = 0;
};

struct ConnectionThread {
  std::thread thread;
  std::shared_ptr<std::atomic<bool>> done = std::make_shared<std::atomic<bool>>(false);
};

struct Server::State {
  ServerConfig config;
  // Read and replaced with std::atomic_load / atomic_store (Server::replace_map): a request
  // holds its own reference, so it finishes on the map it started with.
  std::shared_ptr<const LoadedMap> map;
  std::shared_ptr<const LoadedMap> current_map() const { return std::atomic_load(&map); }
  api::Limits limits;
  api::Socket listener;
  uint16_t port = 0;
  std::string address;
  std::atomic<bool> stopping{false};
  std::unique_ptr<WorkerPool> pool;
  std::thread accept_thread, stats_thread;
  std::mutex connections_mutex;
  std::list<ConnectionThread> connections;
  Stats stats;
  std::unique_ptr<Recent> recent;
  std::mutex stop_mutex;  // serialises stop(); stats_cv waits on it
  std::condition_variable stats_cv;
  bool started = false, stopped = false;

  void log(const std::string& line, LogLevel level = LogLevel::kInfo) const;
};

// Serves one accepted connection until the peer closes, times out, breaks the protocol
// beyond recovery, or the server stops (between frames).
void serve_connection(Server::State& state, api::Socket socket, const std::string& peer);

}  // namespace server
}  // namespace segmatch
