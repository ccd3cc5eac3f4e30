// --request-timeout-s (docs/protocol.md 9): a request that runs past it gets ERROR
// REQUEST_TIMEOUT, its worker stops and takes the next request, and the connection goes on.
#include "server_test_util.h"

#include <chrono>
#include <cstdio>

using namespace segmatch;
using namespace segmatch::testing;

namespace {

// A pathological query: a dense forest of identical poles around the sensor. Every pole is a
// segment that matches every map pole, so the query is slow in every stage after the voxel grid.
api::LocalizeRequest pole_forest(uint64_t id, int per_side) {
  api::LocalizeRequest r;
  r.request_id = id;
  r.sensor_position_local = Eigen::Vector3d(0, 0, 1.8);
  for (int i = 0; i < per_side; ++i)
    for (int j = 0; j < per_side; ++j) {
      const float x = -30.f + 60.f * static_cast<float>(i) / static_cast<float>(per_side);
      const float y = -30.f + 60.f * static_cast<float>(j) / static_cast<float>(per_side);
      for (float z = 0.f; z < 3.f; z += 0.04f)
        for (int k = 0; k < 16; ++k) {
          const float a = 2.f * static_cast<float>(M_PI) * static_cast<float>(k) / 16.f;
          r.points.push_back(Point{x + 0.15f * std::cos(a), y + 0.15f * std::sin(a), z, 0.f});
        }
    }
  return r;
}

// A query that is answered at once (too few segments): the worker's next request.
api::LocalizeRequest tiny_request(uint64_t id) {
  api::LocalizeRequest r;
  r.request_id = id;
  for (int i = 0; i < 20; ++i) r.points.push_back(Point{0.05f * static_cast<float>(i), 1.f, 1.f, 0.f});
  return r;
}

server::ServerConfig one_worker(double request_timeout_s) {
  server::ServerConfig config;
  config.workers = 1;
  config.request_timeout_s = request_timeout_s;
  return config;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

// With one worker: the pathological query (many times slower than the timeout) is cut off
// at the timeout with ERROR REQUEST_TIMEOUT, and the next request on the same connection is
// answered within the same timeout. It could not be if the worker were still busy with the
// first, since a request's time counts from its arrival, waiting for a worker included.
TEST(ServerRobustness, ARequestPastItsTimeoutIsStoppedAndFreesItsWorker) {
  RunningServer s(one_worker(0.3));
  api::Client c = s.client();
  const auto t0 = std::chrono::steady_clock::now();
  try {
    c.localize(pole_forest(1, 30));
    FAIL() << "the pole forest was answered within 0.3 s; make it larger";
  } catch (const api::ClientError& e) {
    EXPECT_EQ(e.kind, api::ClientError::Kind::kServer) << e.what();
    EXPECT_EQ(e.server_code, api::ErrorCode::kRequestTimeout) << e.what();
    EXPECT_NE(std::string(e.what()).find("request timed out: the query's deadline passed"), std::string::npos)
        << e.what();
  }
  std::printf("pole forest stopped after %.2f s (client's encoding and sending included)\n", seconds_since(t0));
  for (const std::string& line : s.log_lines()) std::printf("  server: %s\n", line.c_str());
  const api::LocalizeReply next = c.localize(tiny_request(2));  // same connection, same worker
  EXPECT_EQ(next.request_id, 2u);
  EXPECT_EQ(next.status, api::LocalizeStatus::kNotLocalized) << next.reason;
  EXPECT_EQ(c.ping(7), 7u);
  const server::ServerCounters counters = s.server->counters();
  EXPECT_EQ(counters.timed_out, 1u);
  EXPECT_EQ(counters.errors, 1u);
}

// Without a limit (0), a slow query (a smaller forest) runs to its answer.
TEST(ServerRobustness, NoTimeoutLetsASlowQueryFinish) {
  RunningServer s(one_worker(0));
  api::Client c = s.client();
  const api::LocalizeReply r = c.localize(pole_forest(3, 12));
  EXPECT_EQ(r.request_id, 3u);
  EXPECT_NE(r.status, api::LocalizeStatus::kLocalized) << "a forest of identical poles is ambiguous";
  EXPECT_EQ(s.server->counters().timed_out, 0u);
}
