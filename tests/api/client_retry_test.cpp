// ClientOptions::retries: a request whose connection is lost before the reply is sent again on
// a new connection; timeouts and ERROR replies are not retried. Against a scripted server that
// drops the first connections after reading their request.
#include "segmatch/api/client.h"

#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>

using namespace segmatch;
using namespace segmatch::api;

namespace {

// Accepts connections on a loopback port. Connections numbered in `close_at_once` (from 1) are
// closed before anything is read, like a dying replica's backlog. On the others it answers HELLO
// with HELLO_OK, then reads one request and, while `drops` lasts, closes without a reply, else
// answers LOCALIZE_REPLY (or ERROR kInternal when `error_reply`) for the request's id.
class ScriptedServer {
 public:
  explicit ScriptedServer(int drops, bool error_reply = false, std::vector<int> close_at_once = {})
      : drops_(drops), error_reply_(error_reply), close_at_once_(std::move(close_at_once)) {
    listener_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t len = sizeof(a);
    if (::bind(listener_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 || ::listen(listener_, 8) != 0 ||
        ::getsockname(listener_, reinterpret_cast<sockaddr*>(&a), &len) != 0)
      throw std::runtime_error("ScriptedServer: cannot listen");
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] { serve(); });
  }
  ~ScriptedServer() {
    ::shutdown(listener_, SHUT_RDWR);
    ::close(listener_);
    thread_.join();
  }
  uint16_t port() const { return port_; }
  int connections() const { return connections_; }
  int hellos() const { return hellos_; }

 private:
  // One frame; false when the connection ended first.
  static bool read_frame(int fd, Header& header, std::vector<uint8_t>& payload) {
    uint8_t header_bytes[kHeaderBytes];
    const auto deadline = deadline_after(5);
    if (read_exact(fd, header_bytes, kHeaderBytes, deadline) != IoResult::kOk ||
        decode_header(header_bytes, kHeaderBytes, Limits{}, header) != DecodeStatus::kOk)
      return false;
    payload.resize(header.payload_bytes);
    return read_exact(fd, payload.data(), payload.size(), deadline) == IoResult::kOk;
  }
  void answer(int fd, const std::vector<uint8_t>& payload) {
    LocalizeRequest request;
    decode(payload.data(), payload.size(), Limits{}, request);
    LocalizeReply reply;
    reply.request_id = request.request_id;
    reply.status = LocalizeStatus::kNotLocalized;
    reply.reason = "scripted";
    const std::vector<uint8_t> out =
        error_reply_ ? encode(ErrorReply{ErrorCode::kInternal, "scripted failure"}) : encode(reply);
    write_all(fd, out.data(), out.size(), deadline_after(5));
  }
  void serve() {
    for (;;) {
      const int fd = ::accept(listener_, nullptr, nullptr);
      if (fd < 0) return;
      const int number = ++connections_;
      Header header;
      std::vector<uint8_t> payload;
      const bool dying = std::find(close_at_once_.begin(), close_at_once_.end(), number) != close_at_once_.end();
      while (!dying && read_frame(fd, header, payload)) {
        if (header.type == static_cast<uint16_t>(MessageType::kHello)) {
          ++hellos_;
          const std::vector<uint8_t> ok = encode(HelloOkReply{});
          write_all(fd, ok.data(), ok.size(), deadline_after(5));
          continue;
        }
        if (drops_-- <= 0) answer(fd, payload);
        break;
      }
      ::close(fd);
    }
  }
  int listener_ = -1;
  uint16_t port_ = 0;
  std::atomic<int> drops_, connections_{0}, hellos_{0};
  bool error_reply_;
  std::vector<int> close_at_once_;
  std::thread thread_;
};

LocalizeRequest request(uint64_t id) {
  LocalizeRequest r;
  r.request_id = id;
  r.points.push_back(Point{1.f, 2.f, 3.f, 0.f});
  return r;
}

}  // namespace

TEST(ClientRetry, ALostConnectionIsRetriedOnceOnANewOne) {
  ScriptedServer server(1);
  Client client("127.0.0.1", server.port());
  const LocalizeReply reply = client.localize(request(5));
  EXPECT_EQ(reply.request_id, 5u);
  EXPECT_EQ(reply.reason, "scripted");
  EXPECT_EQ(client.retries_used(), 1);
  EXPECT_EQ(server.connections(), 2);
  EXPECT_EQ(server.hellos(), 1) << "the retry's connection is proven live by a HELLO first";
}

// Behind a balancer, a retry may first reach a replica that is going away: its connection is
// closed before HELLO_OK. That attempt is made again after a pause; the one retry is kept for a
// server that answers.
TEST(ClientRetry, ARetryReconnectsUntilAServerAnswersHello) {
  ScriptedServer server(1, false, {2, 3});
  Client client("127.0.0.1", server.port());
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(client.localize(request(11)).request_id, 11u);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(client.retries_used(), 1);
  EXPECT_EQ(server.connections(), 4);
  EXPECT_GE(seconds, 0.15) << "pauses of 50 and 100 ms between the attempts";

  // Nobody answering HELLO within the window: a connection error, not a hang.
  ScriptedServer gone(1, false, {2, 3, 4, 5, 6, 7, 8, 9, 10});
  ClientOptions options;
  options.reconnect_window_s = 0.3;
  Client doomed("127.0.0.1", gone.port(), options);
  try {
    doomed.localize(request(12));
    FAIL() << "no server answered HELLO";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind, ClientError::Kind::kClosed) << e.what();
  }
  EXPECT_LE(gone.connections(), 5);
}

TEST(ClientRetry, ASecondLossIsReportedAfterTheOneRetry) {
  ScriptedServer server(2);
  Client client("127.0.0.1", server.port());
  try {
    client.localize(request(6));
    FAIL() << "two lost connections with one retry must throw";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind, ClientError::Kind::kClosed) << e.what();
  }
  EXPECT_EQ(client.retries_used(), 1);
  EXPECT_EQ(server.connections(), 2);
  // The next call connects again (the scripted server now answers).
  EXPECT_EQ(client.localize(request(7)).request_id, 7u);
  EXPECT_EQ(server.connections(), 3);
}

TEST(ClientRetry, NoRetriesWhenTurnedOff) {
  ScriptedServer server(1);
  ClientOptions options;
  options.retries = 0;
  Client client("127.0.0.1", server.port(), options);
  EXPECT_THROW(client.localize(request(8)), ClientError);
  EXPECT_THROW(client.localize(request(9)), ClientError) << "broken, and no reconnect without retries";
  EXPECT_EQ(client.retries_used(), 0);
  EXPECT_EQ(server.connections(), 1);
  options.retries = -1;
  EXPECT_THROW(Client("127.0.0.1", server.port(), options), std::invalid_argument);
}

TEST(ClientRetry, AnErrorReplyIsNotRetried) {
  ScriptedServer server(0, /*error_reply=*/true);
  Client client("127.0.0.1", server.port());
  try {
    client.localize(request(10));
    FAIL() << "an ERROR reply must throw";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.kind, ClientError::Kind::kServer) << e.what();
  }
  EXPECT_EQ(client.retries_used(), 0);
  EXPECT_EQ(server.connections(), 1);
}
