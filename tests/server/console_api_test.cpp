// The operator's page's JSON API (docs/console.md) and what bad HTTP clients get:
// 4xx answers, never a disturbed localization port.
#include "server/http_util.h"
#include "server_test_util.h"

#include <segmatch/server/console.h>
#include <segmatch/server/metrics.h>

#include <nlohmann/json.hpp>

#include <thread>

using namespace segmatch;
using namespace segmatch::testing;
using nlohmann::json;

namespace {

const std::string kToken = "console-test-token";
const std::string kAuth = "Authorization: Bearer " + kToken + "\r\n";

struct ConsoleServer {
  explicit ConsoleServer(server::ConsoleConfig console = {}, size_t recent_answers = 4096) : s(config(recent_answers)) {
    console.token = kToken;
    console.metrics = metrics;
    page = std::make_unique<server::Console>(console, *s.server);
  }
  server::ServerConfig config(size_t recent_answers) {
    server::ServerConfig c;
    c.token = kToken;
    c.metrics = metrics;
    c.recent_answers = recent_answers;
    return c;
  }
  json get(const std::string& target) {
    const HttpReply r = http_get(page->port(), target, kAuth);
    EXPECT_EQ(r.status, 200) << target << ": " << r.head << "\n" << r.body;
    return json::parse(r.body, nullptr, false);
  }
  std::shared_ptr<server::Metrics> metrics = std::make_shared<server::Metrics>();
  RunningServer s;
  std::unique_ptr<server::Console> page;
};

// A request the localizer refuses (one point), with a prior: the page draws it at its prior.
api::LocalizeRequest refused_request(uint64_t id, const Eigen::Vector3d& at) {
  api::LocalizeRequest r;
  r.request_id = id;
  r.flags = api::kFlagHasPrior;
  r.T_map_local_prior = Pose3d::Identity();
  r.T_map_local_prior.translation() = at;
  r.prior_radius_m = 5.0;
  r.points.push_back(Point{1.f, 1.f, 1.f, 0.f});
  return r;
}

}  // namespace

TEST(ServerConsole, RecentRingKeepsTheLastAnswersAndCountsAll) {
  server::Recent recent(4, 3);
  for (int i = 0; i < 10; ++i) {
    server::Answer a;
    a.type = "LOCALIZE";
    a.status = i % 2 ? "localized" : "not_localized";
    a.refusal = i % 2 ? "NONE" : "TOO_FEW_SEGMENTS";
    a.latency_ms = i;
    recent.add(a);
  }
  uint64_t next = 0, missed = 0;
  std::vector<server::Answer> got = recent.since(0, 100, next, missed);
  ASSERT_EQ(got.size(), 4u);
  EXPECT_EQ(got.front().cursor, 7u);
  EXPECT_EQ(next, 10u);
  EXPECT_EQ(missed, 6u);
  EXPECT_TRUE(recent.since(next, 100, next, missed).empty());
  EXPECT_EQ(next, 10u);
  got = recent.since(8, 1, next, missed);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].cursor, 9u);
  EXPECT_EQ(next, 9u);
  const server::RecentStats st = recent.stats();
  EXPECT_EQ(st.answered, 10u);
  EXPECT_EQ(st.by_type_status.at("LOCALIZE/localized"), 5u);
  EXPECT_EQ(st.refusals.at("TOO_FEW_SEGMENTS"), 5u);
  EXPECT_EQ(st.latency_samples, 3u);  // the window: the last three latencies, 7 8 9
  EXPECT_EQ(st.p50_ms, 8.0);
  EXPECT_EQ(st.p99_ms, 9.0);
}

TEST(ServerConsole, ApiServesMapTilesAnswersAndStats) {
  ConsoleServer cs;
  const server::LoadedMap& map = *cs.s.server->map();
  const json m = cs.get("/api/map");
  EXPECT_EQ(m["name"], "tiny-3");
  EXPECT_EQ(m["segments"], map.segment_count());
  EXPECT_EQ(m["schema"], map.schema_version);
  EXPECT_TRUE(m["parameters"].is_object());
  EXPECT_NEAR(m["bounds"]["min"][0].get<double>(), map.extent_min.x(), 1e-6);
  // Every segment is in exactly one tile of a level: the tiles over the bounds at level 5 hold
  // them all (128 m tiles, none sampled on this small map).
  const double size_m = 4096.0 / 32;
  size_t total = 0;
  for (int64_t x = std::floor(map.extent_min.x() / size_m); x <= std::floor(map.extent_max.x() / size_m); ++x)
    for (int64_t y = std::floor(map.extent_min.y() / size_m); y <= std::floor(map.extent_max.y() / size_m); ++y) {
      const json t = cs.get("/api/tiles/5/" + std::to_string(x) + "/" + std::to_string(y));
      EXPECT_FALSE(t["sampled"].get<bool>());
      EXPECT_EQ(t["segments"].size(), t["total"].get<size_t>());
      total += t["segments"].size();
    }
  EXPECT_EQ(total, map.segment_count());
  const json coarse = cs.get("/api/tiles/0/0/0");  // one tile over the whole map? not required; well-formed
  EXPECT_TRUE(coarse["segments"].is_array());

  api::Client c = cs.s.client(kToken);
  const api::LocalizeReply refused = c.localize(refused_request(77, map.extent_min + Eigen::Vector3d(5, 5, 0)));
  EXPECT_NE(refused.status, api::LocalizeStatus::kLocalized);
  EXPECT_EQ(refused.refusal, api::RefusalCode::kNone);  // not asked for: the reply is as before
  EXPECT_FALSE(refused.detail.has_value());
  json a = cs.get("/api/answers?since=0");
  ASSERT_EQ(a["answers"].size(), 1u) << a.dump();
  const json& answer = a["answers"][0];
  EXPECT_EQ(answer["request_id"], 77);
  EXPECT_EQ(answer["status"], api::to_string(refused.status));
  EXPECT_NE(answer["refusal"], "NONE");  // the page always has the code
  EXPECT_EQ(answer["reason"], refused.reason);
  EXPECT_TRUE(answer["pose"]["from_prior"].get<bool>());
  EXPECT_NEAR(answer["pose"]["x"].get<double>(), map.extent_min.x() + 5, 1e-6);
  const uint64_t cursor = a["cursor"];
  EXPECT_TRUE(cs.get("/api/answers?since=" + std::to_string(cursor))["answers"].empty());
  const json st = cs.get("/api/stats");
  EXPECT_EQ(st["counters"]["localize_requests"], cs.s.server->counters().localize_requests);
  EXPECT_EQ(st["localization"]["refusals"][answer["refusal"].get<std::string>()], 1);
}

TEST(ServerConsole, BadRequestsGet4xxAndNeverDisturbLocalization) {
  server::ConsoleConfig console;
  console.threads = 2;
  console.request_timeout_ms = 300;  // slow clients are dropped after this
  console.max_request_bytes = 8192;
  ConsoleServer cs(console);
  const uint16_t port = cs.page->port();
  EXPECT_EQ(http_get(port, "/nope", kAuth).status, 404);
  EXPECT_EQ(http_get(port, "/api/tiles/99/0/0", kAuth).status, 400);
  EXPECT_EQ(http_get(port, "/api/tiles/3/x/0", kAuth).status, 400);
  EXPECT_EQ(http_get(port, "/api/tiles/3/0", kAuth).status, 400);
  EXPECT_EQ(http_get(port, "/api/tiles/3/99999999999/0", kAuth).status, 400);
  EXPECT_EQ(http_get(port, "/api/answers?since=-1", kAuth).status, 400);
  EXPECT_EQ(http_get(port, "/api/answers?max=0", kAuth).status, 400);
  {
    RawHttp post(port);
    post.send("POST /api/stats HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nConnection: close\r\n" + kAuth + "\r\n{}");
    EXPECT_EQ(post.read(10).status, 405);
  }
  const HttpReply huge = http_get(port, "/api/stats", kAuth + "X-Big: " + std::string(20000, 'a') + "\r\n");
  EXPECT_GE(huge.status, 400) << huge.head;
  EXPECT_LT(huge.status, 500) << huge.head;
  // Slow clients: more than the HTTP threads, each sending half a request line and waiting.
  std::vector<std::unique_ptr<RawHttp>> slow;
  for (int i = 0; i < 4; ++i) {
    slow.push_back(std::make_unique<RawHttp>(port));
    slow.back()->send("GET /api/st");
  }
  // Meanwhile the localization port answers as ever.
  api::Client c = cs.s.client(kToken);
  EXPECT_EQ(c.ping(5), 5u);
  EXPECT_EQ(c.localize(test_world().queries().front().request).status, api::LocalizeStatus::kLocalized);
  // Each slow client is dropped by the server (a 408 or a plain close), not served forever.
  for (auto& s : slow) {
    const HttpReply r = s->read(30.0);
    EXPECT_TRUE(r.closed);
    EXPECT_TRUE(r.status == 0 || (r.status >= 400 && r.status < 500)) << r.head;
  }
  EXPECT_EQ(http_get(port, "/api/stats", kAuth).status, 200);  // and the page is back
  EXPECT_EQ(cs.s.server->counters().errors, 0u);
}

// Every path answers 401 without the token, the page's own files too; the page opened as
// /?token=T names its script and style sheet with the token (percent-encoded), and a browser's
// requests for them so pass.
TEST(ServerConsole, EveryPathNeedsTheToken) {
  ConsoleServer cs;
  const uint16_t port = cs.page->port();
  for (const std::string path : {"/", "/index.html", "/app.js", "/style.css", "/api/map", "/api/stats", "/api/answers",
                                 "/api/tiles/5/0/0", "/metrics", "/nope"}) {
    const HttpReply none = http_get(port, path);
    EXPECT_EQ(none.status, 401) << path;
    EXPECT_NE(none.head.find("WWW-Authenticate: Bearer"), std::string::npos) << path << ": " << none.head;
    EXPECT_EQ(json::parse(none.body, nullptr, false).value("status", 0), 401) << path << ": " << none.body;
    EXPECT_EQ(http_get(port, path, "Authorization: Bearer wrong\r\n").status, 401) << path;
    EXPECT_EQ(http_get(port, path + "?token=wrong").status, 401) << path;
    EXPECT_EQ(http_get(port, path + "?token=" + kToken.substr(1)).status, 401) << path;
    const int expected = path == "/nope" ? 404 : 200;
    EXPECT_EQ(http_get(port, path + "?token=" + kToken).status, expected) << path;
    EXPECT_EQ(http_get(port, path, kAuth).status, expected) << path;
  }
  EXPECT_NE(http_get(port, "/?token=" + kToken).body.find("src=\"app.js?token=" + kToken + "\""), std::string::npos);
  // Fetched with the header (a proxy adding it), the page does not hand the token to the browser.
  const HttpReply proxied = http_get(port, "/", kAuth);
  EXPECT_NE(proxied.body.find("src=\"app.js\""), std::string::npos) << proxied.body;
  EXPECT_EQ(proxied.body.find(kToken), std::string::npos) << proxied.body;

  // A token with bytes that mean something in a URL or in HTML.
  server::ConsoleConfig odd;
  odd.token = "a b&c<d\"e%f+";
  auto odd_page = std::make_unique<server::Console>(odd, *cs.s.server);
  // civetweb (mg_url_encode) writes lowercase hex digits: equivalent to uppercase (RFC 3986 2.1).
  const std::string encoded = "a%20b%26c%3cd%22e%25f%2b";
  const HttpReply html = http_get(odd_page->port(), "/?token=" + encoded);
  ASSERT_EQ(html.status, 200) << html.head;
  EXPECT_NE(html.body.find("href=\"style.css?token=" + encoded + "\""), std::string::npos) << html.body;
  EXPECT_NE(html.body.find("src=\"app.js?token=" + encoded + "\""), std::string::npos) << html.body;
  EXPECT_EQ(html.body.find("{{"), std::string::npos);
  EXPECT_EQ(http_get(odd_page->port(), "/app.js?token=" + encoded).status, 200);
  EXPECT_EQ(http_get(odd_page->port(), "/style.css", "Authorization: Bearer " + odd.token + "\r\n").status, 200);

  // Without a token everything is served, and the page's addresses carry none.
  auto no_token = std::make_unique<server::Console>(server::ConsoleConfig{}, *cs.s.server);
  const HttpReply plain = http_get(no_token->port(), "/");
  EXPECT_EQ(plain.status, 200);
  EXPECT_NE(plain.body.find("src=\"app.js\""), std::string::npos) << plain.body;
  EXPECT_EQ(http_get(no_token->port(), "/api/map").status, 200);
  // Stopping a console takes up to 2 s (civetweb's listener polls that long): these two stop
  // side by side.
  std::thread stop([&] { odd_page.reset(); });
  no_token.reset();
  stop.join();
}

TEST(ServerConsole, MetricsShareTheHttpPort) {
  ConsoleServer cs;
  cs.s.client(kToken).ping(1);
  const HttpReply r = http_get(cs.page->port(), "/metrics", kAuth);
  EXPECT_EQ(r.status, 200);
  EXPECT_NE(r.body.find("segmatch_requests_total{status=\"ok\",type=\"PING\"} 1"), std::string::npos) << r.body;
}
