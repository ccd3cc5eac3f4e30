// Prometheus metrics of a segmatch-server, served over HTTP by prometheus-cpp (Debian's
// prometheus-cpp-dev: its registry, text format and civetweb exposer), GET /metrics:
//   segmatch_requests_total{type,status}     frames answered: type LOCALIZE, PING, ...; status
//                                            localized / not_localized / outside_prior / ok / error
//   segmatch_errors_total{code}              ERROR replies by protocol code (docs/protocol.md 7)
//   segmatch_request_duration_seconds        histogram of LOCALIZE and LOCALIZE_SEGMENTS, frame
//                                            received to reply ready
//   segmatch_in_flight_requests              localizations received and not yet answered
//   segmatch_connections                     connections open
//   segmatch_map_info{name,schema,segments}  1, for the map being served
//   segmatch_uptime_seconds                  since the server started
// The prometheus-cpp types stay in metrics.cpp (this header is included by the server's sources).
#pragma once

#include <cstdint>
#include <memory>
#include <string>

namespace segmatch {
namespace server {

class Metrics {
 public:
  // Listens on listen_address:port (port 0: a free one, see port()). Throws std::runtime_error
  // when it cannot.
  Metrics(const std::string& listen_address, uint16_t port);
  // Counted but not served on a port of its own: text() only (the operator's page's HTTP port
  // serves it, console.h).
  Metrics();
  ~Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;
  uint16_t port() const;  // 0 without a port of its own

  // Thread-safe, called by the server as frames are answered and connections come and go.
  void request(const std::string& type, const std::string& status, double seconds, bool is_localize);
  void error(uint16_t code);
  void in_flight(int delta);
  void connections(int delta);
  void map(const std::string& name, int schema, size_t segments);  // replaces the previous one
  // What GET /metrics answers, in Prometheus' text format: the operator's page's HTTP port
  // serves it too (console.h), so one port may carry both.
  std::string text() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace server
}  // namespace segmatch
