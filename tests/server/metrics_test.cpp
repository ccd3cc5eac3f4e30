// --metrics-port: the Prometheus endpoint, scraped with curl as a Prometheus server
// would, counts exactly the frames a client sent.
#include "server_test_util.h"
#include "support/run_command.h"

#include <segmatch/server/metrics.h>

#include <thread>

using namespace segmatch;
using namespace segmatch::testing;

namespace {

std::string scrape(uint16_t port) {
  const test::CommandResult r = test::run_command("curl -sS http://127.0.0.1:" + std::to_string(port) + "/metrics");
  EXPECT_EQ(r.code, 0) << r.output;
  return r.output;
}

// The value of the sample whose line starts with `series` ("name{labels}" or "name").
double sample(const std::string& text, const std::string& series) {
  const size_t at = text.find("\n" + series + " ");
  if (at == std::string::npos) return -1.0;
  return std::stod(text.substr(at + series.size() + 2));
}

}  // namespace

TEST(ServerRobustness, MetricsCountTheFramesSent) {
  server::ServerConfig config;
  config.metrics = std::make_shared<server::Metrics>("127.0.0.1", 0);
  const uint16_t port = config.metrics->port();
  ASSERT_GT(port, 0);
  RunningServer s(config);
  {
    api::Client c = s.client();
    for (int i = 0; i < 3; ++i) c.ping(i);
    c.info();
    EXPECT_EQ(c.localize(test_world().queries().front().request).status, api::LocalizeStatus::kLocalized);
    api::LocalizeRequest few;
    few.request_id = 2;
    few.points.push_back(Point{1.f, 1.f, 1.f, 0.f});
    EXPECT_EQ(c.localize(few).status, api::LocalizeStatus::kNotLocalized);
    std::vector<uint8_t> malformed = api::encode(api::PingRequest{9});
    malformed.push_back(0);  // a trailing byte: MALFORMED (code 4), the connection stays
    malformed[8] = 9;        // payload length, u32 little-endian
    c.send_raw(malformed);
    EXPECT_EQ(c.read_frame().header.type, static_cast<uint16_t>(api::MessageType::kError));
    const std::string open = scrape(port);
    EXPECT_EQ(sample(open, "segmatch_connections"), 1.0) << open;
  }
  std::string text;
  for (int i = 0; i < 200; ++i) {  // the server notices the closed connection on its own thread
    text = scrape(port);
    if (sample(text, "segmatch_connections") == 0.0) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(sample(text, R"(segmatch_requests_total{status="ok",type="PING"})"), 3.0) << text;
  EXPECT_EQ(sample(text, R"(segmatch_requests_total{status="error",type="PING"})"), 1.0) << text;
  EXPECT_EQ(sample(text, R"(segmatch_requests_total{status="ok",type="INFO"})"), 1.0) << text;
  EXPECT_EQ(sample(text, R"(segmatch_requests_total{status="localized",type="LOCALIZE"})"), 1.0) << text;
  EXPECT_EQ(sample(text, R"(segmatch_requests_total{status="not_localized",type="LOCALIZE"})"), 1.0) << text;
  EXPECT_EQ(sample(text, R"(segmatch_errors_total{code="4"})"), 1.0) << text;
  EXPECT_EQ(sample(text, "segmatch_request_duration_seconds_count"), 2.0) << text;
  EXPECT_EQ(sample(text, "segmatch_in_flight_requests"), 0.0) << text;
  EXPECT_EQ(sample(text, "segmatch_connections"), 0.0) << text;
  const std::string map_info = R"(segmatch_map_info{name="tiny-3",schema=")" + std::to_string(storage::kSchemaVersion) +
                               R"(",segments=")" + std::to_string(s.server->map()->segment_count()) + "\"}";
  EXPECT_EQ(sample(text, map_info), 1.0) << text;
  EXPECT_GT(sample(text, "segmatch_uptime_seconds"), 0.0) << text;
}
