// The operator's page over civetweb: options that bound what a client can cost, one handler
// that authenticates and routes every request, answers with explicit lengths (keep-alive).
#include "segmatch/server/console.h"

#include "console_api.h"
#include "console_assets.h"
#include "console_tiles.h"

#include "segmatch/server/metrics.h"
#include "segmatch/server/server.h"

#include <civetweb.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstring>
#include <mutex>
#include <stdexcept>

namespace segmatch {
namespace server {

struct Console::Impl {
  Impl(const ConsoleConfig& c, const Server& s) : config(c), server(s), tiles(c.tile_cache_entries) {}
  ConsoleConfig config;
  const Server& server;
  TileCache tiles;
  const std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now();
  mg_context* context = nullptr;
  uint16_t port = 0;
  std::mutex log_mutex;
  std::string last_log;  // civetweb's last message: why mg_start failed
};

namespace {

using Impl = Console::Impl;

// The page is only ever fetched from this port: scripts and styles from 'self', nothing else.
constexpr const char* kSecurityPolicy =
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'";

void respond(mg_connection* c, int status, const char* content_type, const std::string& body,
             const char* extra_name = nullptr, const char* extra_value = nullptr) {
  mg_response_header_start(c, status);
  mg_response_header_add(c, "Content-Type", content_type, -1);
  mg_response_header_add(c, "Content-Length", std::to_string(body.size()).c_str(), -1);
  mg_response_header_add(c, "Cache-Control", "no-store", -1);
  mg_response_header_add(c, "X-Content-Type-Options", "nosniff", -1);
  mg_response_header_add(c, "Content-Security-Policy", kSecurityPolicy, -1);
  // The page's address may hold the token (?token=): never pass it on as a Referer.
  mg_response_header_add(c, "Referrer-Policy", "no-referrer", -1);
  if (extra_name) mg_response_header_add(c, extra_name, extra_value, -1);
  mg_response_header_send(c);
  mg_write(c, body.data(), body.size());
}

int fail(mg_connection* c, int status, const std::string& why, const char* extra_name = nullptr,
         const char* extra_value = nullptr) {
  respond(
      c, status, "application/json",
      nlohmann::json{{"error", why}, {"status", status}}.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
      extra_name, extra_value);
  return status;
}

int ok_json(mg_connection* c, const std::string& body) {
  respond(c, 200, "application/json", body);
  return 200;
}

// No early exit on the first differing byte (as the localization port's HELLO).
bool same_token(const std::string& given, const std::string& expected) {
  if (given.size() != expected.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < given.size(); ++i) diff |= static_cast<unsigned char>(given[i] ^ expected[i]);
  return diff == 0;
}

bool authorized(const Impl& impl, mg_connection* c, const mg_request_info& ri) {
  if (impl.config.token.empty()) return true;
  const char* header = mg_get_header(c, "Authorization");
  if (header && std::strncmp(header, "Bearer ", 7) == 0 && same_token(header + 7, impl.config.token)) return true;
  return same_token(query_value(ri.query_string, "token"), impl.config.token);
}

// The token as a query value, percent-encoded by civetweb (its kept characters are none of
// '"', '<', '>' or '&', so the result is also safe inside an HTML attribute).
std::string url_encoded(const std::string& text) {
  std::string out(3 * text.size() + 1, '\0');
  const int n = mg_url_encode(text.c_str(), out.data(), out.size());
  if (n < 0) throw std::runtime_error("console: the token could not be URL-encoded");
  out.resize(static_cast<size_t>(n));
  return out;
}

// A browser loads the page's script and style sheet by their addresses in index.html, with no
// header of ours: when the page was opened as /?token=TOKEN those addresses carry it on (the
// placeholder {{token_query}}). Only then: a page fetched with the header (a proxy that adds
// it, docs/console.md) names its files without the token, which never reaches the browser.
std::string asset_body(const Impl& impl, const ConsoleAsset& asset, const mg_request_info& ri) {
  std::string body(reinterpret_cast<const char*>(asset.data), asset.size);
  const std::string placeholder = "{{token_query}}";
  const bool in_query =
      !impl.config.token.empty() && same_token(query_value(ri.query_string, "token"), impl.config.token);
  const std::string query = in_query ? "?token=" + url_encoded(impl.config.token) : "";
  for (size_t at = body.find(placeholder); at != std::string::npos; at = body.find(placeholder, at + query.size()))
    body.replace(at, placeholder.size(), query);
  return body;
}

// /api/tiles/Z/X/Y
int serve_tile(Impl& impl, mg_connection* c, const std::string& rest) {
  const size_t a = rest.find('/'), b = a == std::string::npos ? a : rest.find('/', a + 1);
  if (b == std::string::npos || rest.find('/', b + 1) != std::string::npos)
    return fail(c, 400, "a tile is /api/tiles/Z/X/Y");
  const std::optional<uint64_t> z = parse_count(rest.substr(0, a), kTileMaxLevel);
  if (!z) return fail(c, 400, "tile level must be 0.." + std::to_string(kTileMaxLevel));
  // Tiles within 4096 x 4096 root tiles of the origin (16 800 km): beyond, no map has segments.
  const int64_t limit = int64_t{1} << (*z + 12);
  const std::optional<int64_t> x = parse_int(rest.substr(a + 1, b - a - 1), limit);
  const std::optional<int64_t> y = parse_int(rest.substr(b + 1), limit);
  if (!x || !y)
    return fail(c, 400, "tile x and y must be integers within +-" + std::to_string(limit) + " at this level");
  return ok_json(c, impl.tiles.tile(impl.server.map(), static_cast<int>(*z), *x, *y));
}

int serve_answers(Impl& impl, mg_connection* c, const mg_request_info& ri) {
  const std::string since_text = query_value(ri.query_string, "since"), max_text = query_value(ri.query_string, "max");
  const std::optional<uint64_t> since =
      since_text.empty() ? std::optional<uint64_t>(0) : parse_count(since_text, UINT64_MAX / 2);
  if (!since) return fail(c, 400, "since must be a cursor (a non-negative integer) from a previous answer");
  const uint64_t cap = impl.config.max_answers_per_reply;
  const std::optional<uint64_t> max = max_text.empty() ? std::optional<uint64_t>(cap) : parse_count(max_text, cap);
  if (!max || *max == 0) return fail(c, 400, "max must be 1.." + std::to_string(cap));
  return ok_json(c, answers_json(impl.server.recent(), *since, *max));
}

int route(Impl& impl, mg_connection* c, const mg_request_info& ri) {
  const std::string path = ri.local_uri ? ri.local_uri : "";
  if (path == "/api/map") return ok_json(c, map_json(*impl.server.map()));
  if (path == "/api/stats")
    return ok_json(c, stats_json(impl.server,
                                 std::chrono::duration<double>(std::chrono::steady_clock::now() - impl.start).count()));
  if (path == "/api/answers") return serve_answers(impl, c, ri);
  const std::string tiles = "/api/tiles/";
  if (path.compare(0, tiles.size(), tiles) == 0) return serve_tile(impl, c, path.substr(tiles.size()));
  if (path == "/metrics") {
    if (!impl.config.metrics) return fail(c, 404, "no metrics on this server (segmatch-server --metrics-port)");
    respond(c, 200, "text/plain; version=0.0.4", impl.config.metrics->text());
    return 200;
  }
  return fail(c, 404, "no such page: " + path + " (the API: docs/console.md)");
}

int handle(mg_connection* c, void* data) {
  Impl& impl = *static_cast<Impl*>(data);
  const mg_request_info& ri = *mg_get_request_info(c);
  try {
    if (std::strcmp(ri.request_method, "GET") != 0) return fail(c, 405, "only GET", "Allow", "GET");
    // Every path needs the token, the page's own files too: whoever reaches the port without
    // it learns nothing, not even which server this is.
    if (!authorized(impl, c, ri))
      return fail(c, 401, "this server needs its token: open /?token=TOKEN, or send Authorization: Bearer TOKEN",
                  "WWW-Authenticate", "Bearer");
    const std::string path = ri.local_uri ? ri.local_uri : "";
    if (const ConsoleAsset* asset = find_console_asset(path == "/" ? "/index.html" : path)) {
      respond(c, 200, asset->content_type, asset_body(impl, *asset, ri));
      return 200;
    }
    return route(impl, c, ri);
  } catch (const std::exception& e) {
    return fail(c, 500, std::string("console: ") + e.what());
  }
}

int keep_log(const mg_connection* c, const char* message) {
  if (Impl* impl = static_cast<Impl*>(mg_get_user_data(mg_get_context(c)))) {
    std::lock_guard<std::mutex> lock(impl->log_mutex);
    impl->last_log = message;
  }
  return 1;  // nothing on stderr: a scanner's bad requests are not the operator's business
}

void check(const ConsoleConfig& c) {
  if (c.threads < 1 || c.threads > 64) throw std::invalid_argument("console threads must be 1..64");
  if (c.request_timeout_ms < 1 || c.keep_alive_timeout_ms < 0)
    throw std::invalid_argument("console timeouts must be > 0");
  if (c.max_request_bytes < 1024) throw std::invalid_argument("console max_request_bytes must be >= 1024");
  if (c.max_answers_per_reply < 1 || c.tile_cache_entries < 1)
    throw std::invalid_argument("console max_answers_per_reply and tile_cache_entries must be >= 1");
}

}  // namespace

Console::Console(const ConsoleConfig& config, const Server& server) : impl_(std::make_unique<Impl>(config, server)) {
  check(config);
  mg_init_library(0);
  const bool v6 = config.listen_address.find(':') != std::string::npos;
  const std::string bind =
      (v6 ? "[" + config.listen_address + "]" : config.listen_address) + ":" + std::to_string(config.port);
  const std::string threads = std::to_string(config.threads), request_ms = std::to_string(config.request_timeout_ms),
                    keep_ms = std::to_string(config.keep_alive_timeout_ms),
                    max_bytes = std::to_string(config.max_request_bytes);
  const char* options[] = {"listening_ports",
                           bind.c_str(),
                           "num_threads",
                           threads.c_str(),
                           "request_timeout_ms",
                           request_ms.c_str(),
                           "keep_alive_timeout_ms",
                           keep_ms.c_str(),
                           "enable_keep_alive",
                           "yes",
                           "max_request_size",
                           max_bytes.c_str(),
                           nullptr};
  mg_callbacks callbacks{};
  callbacks.log_message = keep_log;
  impl_->context = mg_start(&callbacks, impl_.get(), options);
  if (!impl_->context) {
    mg_exit_library();
    throw std::runtime_error("cannot serve the console on " + bind + ": " + impl_->last_log);
  }
  mg_set_request_handler(impl_->context, "/", handle, impl_.get());
  mg_server_port ports[4] = {};
  const int n = mg_get_server_ports(impl_->context, 4, ports);
  impl_->port = n > 0 ? static_cast<uint16_t>(ports[0].port) : 0;
}

Console::~Console() {
  mg_stop(impl_->context);
  mg_exit_library();
}

uint16_t Console::port() const { return impl_->port; }

std::string Console::url() const {
  const std::string& a = impl_->config.listen_address;
  const bool v6 = a.find(':') != std::string::npos;
  return "http://" + (v6 ? "[" + a + "]" : a) + ":" + std::to_string(impl_->port) + "/";
}

}  // namespace server
}  // namespace segmatch
