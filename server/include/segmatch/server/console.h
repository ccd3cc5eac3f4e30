// The operator's page (docs/console.md): an HTTP port (civetweb) serving a
// single-page console compiled into the binary (server/console/: plain JS and a canvas, no
// files read at run time, nothing fetched from elsewhere) and the JSON API it polls under
// /api/: the map, its segments in tiles, the recent answers since a cursor and the statistics.
// With a Metrics it also answers GET /metrics, so one port can carry both.
//
// Cost to localization: the HTTP threads only read what the server keeps anyway (counters,
// the recent-answers ring of recent.h, the map) under short locks; tiles are built once per map
// and cached. Bad requests are answered 4xx by these threads and never reach the localization
// port: headers beyond max_request_bytes get 400, a client that does not send its request
// within request_timeout_ms gets 400 and is dropped, unknown paths 404, other methods than GET 405.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace segmatch {
namespace server {

class Metrics;
class Server;

struct ConsoleConfig {
  std::string listen_address = "127.0.0.1";  // loopback unless another address is asked for
  uint16_t port = 0;                         // 0: a free one, see Console::port()
  // The server's shared secret (ServerConfig::token): every request, the page's own files too,
  // must carry it, as "Authorization: Bearer TOKEN" or "?token=TOKEN"; otherwise 401. A browser
  // opens the page as /?token=TOKEN: the page then names its script and style sheet with the
  // token, and its API calls send the header. Empty: none.
  std::string token;
  int threads = 4;                // HTTP worker threads (each serves one connection at a time)
  int request_timeout_ms = 5000;  // a request (headers) not read whole in this time: dropped
  int keep_alive_timeout_ms = 5000;
  size_t max_request_bytes = 16384;     // request line and headers; beyond: 400
  size_t max_answers_per_reply = 1000;  // /api/answers lists at most this many per call
  size_t tile_cache_entries = 1024;     // tiles' JSON kept (LRU)
  std::shared_ptr<Metrics> metrics;     // also serve GET /metrics from it; null: 404 there
};

class Console {
 public:
  // Starts serving at once; `server` must outlive the console. Throws std::runtime_error when
  // it cannot listen (address in use, bad address), std::invalid_argument for a bad config.
  Console(const ConsoleConfig& config, const Server& server);
  ~Console();  // stops the HTTP threads (requests in progress finish)
  Console(const Console&) = delete;
  Console& operator=(const Console&) = delete;
  uint16_t port() const;
  std::string url() const;  // "http://ADDR:PORT/"

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace server
}  // namespace segmatch
