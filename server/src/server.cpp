// Listening socket, accept loop, stats thread and graceful stop. Frame handling is in
// connection.cpp.
#include "server_state.h"

#include "segmatch/server/metrics.h"

#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <sstream>
#include <stdexcept>

namespace segmatch {
namespace server {

void Stats::record(bool is_localize, bool localized, bool error, bool timed_out, double latency_ms) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.requests;
  ++period_requests_;
  counters_.localize_requests += is_localize;
  counters_.localized += localized;
  counters_.errors += error;
  counters_.timed_out += timed_out;
  if (is_localize && !error) period_latencies_ms_.push_back(latency_ms);
}

void Stats::received() {
  std::lock_guard<std::mutex> lock(mutex_);
  ++counters_.frames_received;
}

void Stats::connection(bool refused) {
  std::lock_guard<std::mutex> lock(mutex_);
  (refused ? counters_.refused_connections : counters_.connections) += 1;
}

ServerCounters Stats::counters() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return counters_;
}

std::string Stats::period_line() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<double>& l = period_latencies_ms_;
  char p50[32] = "-";
  if (!l.empty()) {
    std::nth_element(l.begin(), l.begin() + l.size() / 2, l.end());
    std::snprintf(p50, sizeof(p50), "%.1f", l[l.size() / 2]);
  }
  std::ostringstream s;
  s << "stats: requests=" << counters_.requests << " (+" << period_requests_
    << ") localize=" << counters_.localize_requests << " localized=" << counters_.localized
    << " errors=" << counters_.errors << " timed_out=" << counters_.timed_out
    << " connections=" << counters_.connections << " refused=" << counters_.refused_connections
    << " localize_p50_ms=" << p50 << " (period)";
  l.clear();
  period_requests_ = 0;
  return s.str();
}

void Server::State::log(const std::string& line, LogLevel level) const {
  if (config.log) {
    config.log(line);
    return;
  }
  log_to_stderr(level, line);
}

namespace {

api::Socket listen_on(const std::string& address, uint16_t port, uint16_t& bound_port) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* list = nullptr;
  const std::string where = address + ":" + std::to_string(port);
  const int rc = ::getaddrinfo(address.c_str(), std::to_string(port).c_str(), &hints, &list);
  if (rc != 0) throw std::runtime_error("cannot resolve listen address " + where + ": " + ::gai_strerror(rc));
  api::Socket s(::socket(list->ai_family, list->ai_socktype | SOCK_CLOEXEC, list->ai_protocol));
  const int one = 1;
  std::string error;
  if (!s.valid())
    error = std::strerror(errno);
  else if (::setsockopt(s.fd(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one)) != 0 ||
           ::bind(s.fd(), list->ai_addr, list->ai_addrlen) != 0 || ::listen(s.fd(), 128) != 0)
    error = std::strerror(errno);
  ::freeaddrinfo(list);
  if (!error.empty()) throw std::runtime_error("cannot listen on " + where + ": " + error);
  sockaddr_storage bound{};
  socklen_t len = sizeof(bound);
  ::getsockname(s.fd(), reinterpret_cast<sockaddr*>(&bound), &len);
  bound_port = ntohs(bound.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&bound)->sin6_port
                                                 : reinterpret_cast<sockaddr_in*>(&bound)->sin_port);
  return s;
}

void reap_finished(Server::State& s) {
  std::lock_guard<std::mutex> lock(s.connections_mutex);
  for (auto it = s.connections.begin(); it != s.connections.end();) {
    if (it->done->load()) {
      it->thread.join();
      it = s.connections.erase(it);
    } else {
      ++it;
    }
  }
}

void refuse_busy(Server::State& s, api::Socket socket, const std::string& peer) {
  s.stats.connection(true);
  const std::vector<uint8_t> bytes = api::encode(
      api::ErrorReply{api::ErrorCode::kServerBusy,
                      "server busy: " + std::to_string(s.config.max_connections) + " connections already open"});
  api::write_all(socket.fd(), bytes.data(), bytes.size(), api::deadline_after(1.0));
  s.log(peer + " refused: max connections (" + std::to_string(s.config.max_connections) + ") reached",
        LogLevel::kWarning);
}

void accept_loop(Server::State& s) {
  while (!s.stopping.load()) {
    pollfd p{s.listener.fd(), POLLIN, 0};
    if (::poll(&p, 1, 100) <= 0) continue;
    api::Socket socket(::accept4(s.listener.fd(), nullptr, nullptr, SOCK_CLOEXEC));
    if (!socket.valid()) continue;
    const int one = 1;
    ::setsockopt(socket.fd(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
    const std::string peer = api::peer_address(socket.fd());
    reap_finished(s);
    std::lock_guard<std::mutex> lock(s.connections_mutex);
    if (static_cast<int>(s.connections.size()) >= s.config.max_connections) {
      refuse_busy(s, std::move(socket), peer);
      continue;
    }
    s.stats.connection(false);
    s.connections.emplace_back();
    ConnectionThread& c = s.connections.back();
    c.thread = std::thread([&s, done = c.done, peer, sock = std::make_shared<api::Socket>(std::move(socket))] {
      serve_connection(s, std::move(*sock), peer);
      done->store(true);
    });
  }
}

void stats_loop(Server::State& s) {
  std::unique_lock<std::mutex> lock(s.stop_mutex);
  const auto period = std::chrono::microseconds(static_cast<int64_t>(s.config.stats_interval_s * 1e6));
  while (!s.stats_cv.wait_for(lock, period, [&] { return s.stopped; })) s.log(s.stats.period_line());
}

}  // namespace

Server::Server(const ServerConfig& config, std::shared_ptr<const LoadedMap> map) : state_(std::make_unique<State>()) {
  if (!map || !map->localizer) throw std::invalid_argument("Server needs a loaded map");
  if (config.max_connections < 1) throw std::invalid_argument("max_connections must be >= 1");
  if (!(config.read_timeout_s > 0) || !(config.write_timeout_s > 0))
    throw std::invalid_argument("timeouts must be > 0");
  state_->config = config;
  state_->recent = std::make_unique<Recent>(std::max<size_t>(1, config.recent_answers));
  if (config.metrics) config.metrics->map(map->metadata.name, map->schema_version, map->segment_count());
  state_->map = std::move(map);
  state_->limits.max_payload_bytes = config.max_frame_bytes;
}

Server::~Server() { stop(); }

void Server::start() {
  State& s = *state_;
  std::lock_guard<std::mutex> lock(s.stop_mutex);
  if (s.started) throw std::logic_error("Server::start called twice");
  s.listener = listen_on(s.config.listen_address, s.config.port, s.port);
  const bool v6 = s.config.listen_address.find(':') != std::string::npos;
  s.address = (v6 ? "[" + s.config.listen_address + "]" : s.config.listen_address) + ":" + std::to_string(s.port);
  const int workers = s.config.workers > 0 ? s.config.workers : std::max(1u, std::thread::hardware_concurrency());
  s.pool = std::make_unique<WorkerPool>(workers);
  s.accept_thread = std::thread([&s] { accept_loop(s); });
  if (s.config.stats_interval_s > 0) s.stats_thread = std::thread([&s] { stats_loop(s); });
  s.started = true;
}

uint16_t Server::port() const { return state_->port; }
std::string Server::address() const { return state_->address; }
ServerCounters Server::counters() const { return state_->stats.counters(); }

void Server::replace_map(std::shared_ptr<const LoadedMap> map) {
  if (!map || !map->localizer) throw std::invalid_argument("Server::replace_map needs a loaded map");
  if (state_->config.metrics)
    state_->config.metrics->map(map->metadata.name, map->schema_version, map->segment_count());
  std::atomic_store(&state_->map, std::shared_ptr<const LoadedMap>(std::move(map)));
}

std::shared_ptr<const LoadedMap> Server::map() const { return state_->current_map(); }
const Recent& Server::recent() const { return *state_->recent; }

void Server::stop() {
  State& s = *state_;
  {
    std::lock_guard<std::mutex> lock(s.stop_mutex);
    if (!s.started || s.stopped) return;
    s.stopping.store(true);
  }
  s.accept_thread.join();
  s.listener.close();
  {
    // No new connections can appear now; join every connection (in-flight requests finish).
    std::lock_guard<std::mutex> lock(s.connections_mutex);
    for (ConnectionThread& c : s.connections) c.thread.join();
    s.connections.clear();
  }
  s.pool->shutdown();
  {
    std::lock_guard<std::mutex> lock(s.stop_mutex);
    s.stopped = true;
  }
  s.stats_cv.notify_all();
  if (s.stats_thread.joinable()) s.stats_thread.join();
}

}  // namespace server
}  // namespace segmatch
