// The server under load and abuse: concurrent clients, clients that stall or vanish
// mid-frame, authentication, malformed frames, and a graceful stop with requests in flight.
#include "server_test_util.h"

#include <segmatch/storage/map_types.h>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <cstring>
#include <future>
#include <thread>

using namespace segmatch;
using namespace segmatch::testing;
using Ms = std::chrono::milliseconds;

namespace {

api::LocalizeRequest small_request(uint64_t id) {
  api::LocalizeRequest r = test_world().queries().front().request;
  r.request_id = id;
  r.points.resize(std::min<size_t>(r.points.size(), 3000));
  return r;
}

api::Socket raw_connection(const RunningServer& s) { return api::connect_tcp("127.0.0.1", s.server->port(), Ms(2000)); }

// Next frame on a raw socket, or nullopt if the server closed it.
std::optional<api::Frame> read_raw(const api::Socket& sock, double timeout_s = 5.0) {
  uint8_t header[api::kHeaderBytes];
  const auto deadline = api::deadline_after(timeout_s);
  if (api::read_exact(sock.fd(), header, sizeof(header), deadline) != api::IoResult::kOk) return std::nullopt;
  api::Frame f;
  if (api::decode_header(header, sizeof(header), api::Limits{}, f.header) != api::DecodeStatus::kOk)
    return std::nullopt;
  f.payload.resize(f.header.payload_bytes);
  if (api::read_exact(sock.fd(), f.payload.data(), f.payload.size(), deadline) != api::IoResult::kOk)
    return std::nullopt;
  return f;
}

api::ErrorCode error_code(const api::Frame& f) {
  api::ErrorReply e;
  EXPECT_EQ(f.header.type, static_cast<uint16_t>(api::MessageType::kError));
  EXPECT_EQ(api::decode(f.payload.data(), f.payload.size(), api::Limits{}, e), api::DecodeStatus::kOk);
  return e.code;
}

void send(const api::Socket& sock, const std::vector<uint8_t>& bytes) {
  ASSERT_EQ(api::write_all(sock.fd(), bytes.data(), bytes.size(), api::deadline_after(5)), api::IoResult::kOk);
}

bool closed_by_server(const api::Socket& sock, double timeout_s) {
  uint8_t byte;
  return api::read_exact(sock.fd(), &byte, 1, api::deadline_after(timeout_s)) == api::IoResult::kClosed;
}

}  // namespace

TEST(ServerRobustness, SixteenConcurrentClientsFiftyQueriesEachWithoutError) {
  server::ServerConfig config;
  config.log_requests = false;
  RunningServer s(config);
  std::atomic<int> failures{0}, replies{0};
  std::vector<std::thread> clients;
  for (int c = 0; c < 16; ++c)
    clients.emplace_back([&, c] {
      try {
        api::Client client = s.client();
        for (int i = 0; i < 50; ++i) {
          if (i % 5 == 0) {
            const api::LocalizeReply r = client.localize(small_request(c * 1000 + i));
            replies += r.request_id == static_cast<uint64_t>(c * 1000 + i);
          } else {
            replies += client.ping(c * 1000 + i) == static_cast<uint64_t>(c * 1000 + i);
          }
        }
      } catch (const std::exception& e) {
        ++failures;
        ADD_FAILURE() << "client " << c << ": " << e.what();
      }
    });
  for (std::thread& t : clients) t.join();
  EXPECT_EQ(failures.load(), 0);
  EXPECT_EQ(replies.load(), 16 * 50);
  EXPECT_EQ(s.server->counters().errors, 0u);
  EXPECT_EQ(s.server->counters().requests, 16u * 50u);
}

TEST(ServerRobustness, StalledAndVanishingClientsDoNotDisturbOthers) {
  server::ServerConfig config;
  config.read_timeout_s = 1.0;
  RunningServer s(config);
  api::Socket silent = raw_connection(s);  // connects, sends nothing
  api::Socket half_header = raw_connection(s);
  send(half_header, std::vector<uint8_t>{'S', 'G', 'M'});
  {
    api::Socket vanishing = raw_connection(s);  // announces a big frame, sends part, leaves
    std::vector<uint8_t> frame = api::encode(small_request(1));
    frame.resize(frame.size() / 2);
    send(vanishing, frame);
  }
  api::Client ok = s.client();
  for (int i = 0; i < 20; ++i) {
    const auto start = std::chrono::steady_clock::now();
    ok.ping(i);
    EXPECT_LT(std::chrono::steady_clock::now() - start, Ms(200)) << "a ping waited on another client";
  }
  EXPECT_TRUE(closed_by_server(silent, 3.0)) << "idle connection dropped after read_timeout_s";
  EXPECT_TRUE(closed_by_server(half_header, 3.0));
  // The server still serves: a new connection (ok itself sat idle for more than read_timeout_s
  // while the checks above waited, so the server may rightly have dropped it).
  EXPECT_EQ(s.client().ping(99), 99u);
  const auto log = s.log_lines();
  EXPECT_TRUE(std::any_of(log.begin(), log.end(),
                          [](const std::string& l) { return l.find("frame cut off") != std::string::npos; }));
}

TEST(ServerRobustness, TokenIsRequiredWhenConfigured) {
  server::ServerConfig config;
  config.token = "correct horse battery staple";
  RunningServer s(config);
  EXPECT_EQ(s.client(config.token).ping(7), 7u);
  try {
    s.client("wrong token");
    FAIL() << "wrong token accepted";
  } catch (const api::ClientError& e) {
    EXPECT_EQ(e.kind, api::ClientError::Kind::kServer);
    EXPECT_EQ(e.server_code, api::ErrorCode::kAuthFailed);
  }
  api::Socket sock = raw_connection(s);  // no HELLO
  send(sock, api::encode(api::InfoRequest{}));
  const std::optional<api::Frame> f = read_raw(sock);
  ASSERT_TRUE(f);
  EXPECT_EQ(error_code(*f), api::ErrorCode::kAuthRequired);
  EXPECT_TRUE(closed_by_server(sock, 2.0)) << "unauthenticated connection closed";
  api::Socket unknown = raw_connection(s);  // an unknown type is not a way around HELLO
  std::vector<uint8_t> bytes = api::encode(api::PingRequest{1});
  bytes[6] = 0x42;
  send(unknown, bytes);
  ASSERT_TRUE(read_raw(unknown));
  EXPECT_TRUE(closed_by_server(unknown, 2.0));
}

TEST(ServerRobustness, MalformedFramesGetErrorsAndServingGoesOn) {
  server::ServerConfig config;
  config.max_frame_bytes = 1 << 20;
  RunningServer s(config);
  api::Socket sock = raw_connection(s);
  std::vector<uint8_t> bad_count = api::encode(small_request(5));
  bad_count[api::kHeaderBytes + 132] ^= 1;  // point count off by one
  send(sock, bad_count);
  std::optional<api::Frame> f = read_raw(sock);
  ASSERT_TRUE(f);
  EXPECT_EQ(error_code(*f), api::ErrorCode::kBadPointCount);
  std::vector<uint8_t> nan_point = api::encode(small_request(6));
  const float nan = std::nanf("");
  std::memcpy(&nan_point[api::kHeaderBytes + 140 + 4], &nan, 4);
  send(sock, nan_point);
  ASSERT_TRUE((f = read_raw(sock)));
  EXPECT_EQ(error_code(*f), api::ErrorCode::kNonFinite);
  std::vector<uint8_t> unknown = api::encode(api::PingRequest{1});
  unknown[6] = 0x42;
  send(sock, unknown);
  ASSERT_TRUE((f = read_raw(sock)));
  EXPECT_EQ(error_code(*f), api::ErrorCode::kUnknownType);
  send(sock, api::encode(api::PongReply{1}));  // a reply is no request
  ASSERT_TRUE((f = read_raw(sock)));
  EXPECT_EQ(error_code(*f), api::ErrorCode::kUnexpectedMessage);
  send(sock, api::encode(api::PingRequest{77}));  // the same connection still works
  ASSERT_TRUE((f = read_raw(sock)));
  EXPECT_EQ(f->header.type, static_cast<uint16_t>(api::MessageType::kPong));

  api::Socket big = raw_connection(s);  // over max_frame_bytes: refused before reading it
  api::LocalizeRequest huge = small_request(8);
  huge.points.resize(100000);
  send(big, api::encode(huge));  // the server drains what it refused, so the send completes
  ASSERT_TRUE((f = read_raw(big)));
  EXPECT_EQ(error_code(*f), api::ErrorCode::kFrameTooLarge);
  EXPECT_TRUE(closed_by_server(big, 3.0));
  try {  // what a client library user sees: the server's reason, not "connection reset"
    s.client().localize(huge);
    ADD_FAILURE() << "an oversized request was answered";
  } catch (const api::ClientError& e) {
    EXPECT_EQ(e.kind, api::ClientError::Kind::kServer) << e.what();
    EXPECT_EQ(e.server_code, api::ErrorCode::kFrameTooLarge) << e.what();
  }
  api::Socket garbage = raw_connection(s);
  send(garbage, std::vector<uint8_t>(64, 0xAB));
  ASSERT_TRUE((f = read_raw(garbage)));
  EXPECT_EQ(error_code(*f), api::ErrorCode::kBadMagic);
  EXPECT_TRUE(closed_by_server(garbage, 2.0)) << "a stream without framing cannot be resynchronised";
  EXPECT_EQ(s.client().ping(3), 3u);
  EXPECT_EQ(s.server->counters().errors, 7u);
}

TEST(ServerRobustness, StopFinishesRequestsInFlight) {
  auto s = std::make_unique<RunningServer>();
  const uint16_t port = s->server->port();
  api::Client c = s->client();
  const api::LocalizeRequest request = test_world().queries().front().request;  // a full local cloud
  std::future<api::LocalizeReply> reply = std::async(std::launch::async, [&] { return c.localize(request); });
  // Wait until the server has the whole frame (a fixed sleep lost the race on a loaded machine:
  // the 2-core CI runs two tests at once), then stop while it localizes.
  for (int i = 0; i < 2000 && s->server->counters().frames_received < 1; ++i) std::this_thread::sleep_for(Ms(5));
  ASSERT_GE(s->server->counters().frames_received, 1u) << "the request never arrived";
  api::Client idle = s->client();
  s->server->stop();
  const api::LocalizeReply r = reply.get();  // answered, not dropped
  EXPECT_EQ(r.request_id, request.request_id);
  EXPECT_THROW(api::Client("127.0.0.1", port), api::ClientError) << "no longer accepting";
  EXPECT_THROW(idle.ping(), api::ClientError) << "idle connections are closed";
}

// A map whose point rows are damaged (each one's bytes no longer match its checksum, as after a
// flipped bit on disk): with every point in memory the server refuses to start, naming a row;
// with lazy points it serves, a query whose refinement reads a damaged row gets an ERROR naming
// it, and the connection and the server go on serving.
TEST(ServerRobustness, DamagedPointRowsFailOnlyTheQueriesThatReadThem) {
  const std::string damaged = test_world().folder + "/damaged-points.sqlite";
  std::filesystem::copy_file(test_world().map_path, damaged, std::filesystem::copy_options::overwrite_existing);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(damaged.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE segment_points SET points = points || x'00'", nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);

  server::MapLoadOptions memory;
  memory.points = server::MapPoints::kMemory;
  try {
    server::load_map(damaged, memory);
    ADD_FAILURE() << "a map with damaged points loaded into memory";
  } catch (const storage::StorageError& e) {
    EXPECT_NE(std::string(e.what()).find("segment row"), std::string::npos) << e.what();
  }

  server::ServerConfig config;
  config.listen_address = "127.0.0.1";
  config.port = 0;
  config.workers = 2;
  config.log_requests = false;
  server::Server server(config, server::load_map(damaged));
  server.start();
  api::ClientOptions options;
  options.reply_timeout_s = 60;
  api::Client client("127.0.0.1", server.port(), options);
  int errors = 0;
  for (const Query& q : test_world().queries()) {
    try {
      client.localize(q.request);  // refused before refinement: no point read
    } catch (const api::ClientError& e) {
      ++errors;
      EXPECT_NE(std::string(e.what()).find("segment row"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("points checksum mismatch"), std::string::npos) << e.what();
    }
    EXPECT_EQ(client.ping(7), 7u) << "the connection goes on after an ERROR";
  }
  EXPECT_GE(errors, 3) << "the queries that localize on the healthy map reach refinement";
  server.stop();
  std::filesystem::remove(damaged);
}
