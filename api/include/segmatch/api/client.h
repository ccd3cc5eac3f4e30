// Blocking TCP client of segmatch-server. One Client is one connection at a time (a new one
// when the last was lost: ClientOptions::retries), used from one thread at a time. Every failure throws ClientError
// saying what went wrong; a server ERROR reply carries the server's code and message.
#pragma once

#include <segmatch/api/protocol.h>
#include <segmatch/api/socket_io.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace segmatch {
namespace api {

struct ClientOptions {
  double connect_timeout_s = 5.0;
  // Longest wait for a whole reply (a localization takes ~0.1-1 s; queues add to it).
  double reply_timeout_s = 30.0;
  double send_timeout_s = 30.0;
  std::string token;  // sent in HELLO right after connecting when not empty
  Limits limits;      // for replies
  // A request whose connection is lost before its reply (the server closed or reset it: a
  // replica restarted, a load balancer moved it) is sent again on a new connection, this many
  // times. Every request is idempotent: a LOCALIZE answered twice gives the same answer. Not
  // retried: a timeout (the server may still be working on it), an ERROR reply, a failed
  // connect. A Client whose connection broke earlier reconnects on its next call the same way.
  int retries = 1;
  // The new connection of a retry counts only once a server has answered HELLO (sent with the
  // token, or empty: a server without a token answers any HELLO). A connection refused or
  // closed before HELLO_OK (a replica going away: its backlog still accepts while the process
  // dies) is made again after a pause (50 ms, doubling to 1 s) for this long, without spending
  // the retry or sending the request to it.
  double reconnect_window_s = 5.0;
};

class ClientError : public std::runtime_error {
 public:
  enum class Kind {
    kConnect,   // could not connect / resolve
    kTimeout,   // no (complete) reply in time
    kClosed,    // the server closed the connection
    kProtocol,  // the reply did not decode or was of an unexpected type
    kServer,    // the server answered with ERROR (server_code, message)
  };
  ClientError(Kind kind, const std::string& message, ErrorCode server_code = ErrorCode::kInternal)
      : std::runtime_error(message), kind(kind), server_code(server_code) {}
  Kind kind;
  ErrorCode server_code;
};

struct Frame {
  Header header;
  std::vector<uint8_t> payload;
};

class Client {
 public:
  // Connects and, with a token, authenticates (HELLO -> HELLO_OK). Throws ClientError.
  Client(const std::string& host, uint16_t port, const ClientOptions& options = {});

  // Round trip of one PING; returns the PONG's nonce (equal to the one sent, checked).
  uint64_t ping(uint64_t nonce = 0);
  InfoReply info();
  LocalizeReply localize(const LocalizeRequest& request);
  // Revision 3: the vehicle's own segments (vehicle/segment_query.h makes them). A server of an
  // earlier revision answers UNKNOWN_TYPE (ClientError kServer, code kUnknownType).
  LocalizeReply localize_segments(const LocalizeSegmentsRequest& request);

  // Low level, for tools and tests: send bytes as they are; read the next frame whole.
  void send_raw(const std::vector<uint8_t>& bytes);
  Frame read_frame();

  // After a timeout, a closed connection or an undecodable reply the byte stream is lost: the
  // next call connects again (ClientOptions::retries > 0) or throws kClosed (retries = 0). A
  // server ERROR leaves the connection usable.
  bool broken() const { return broken_; }
  void close() {
    socket_.close();
    broken_ = true;
  }
  // Requests sent again on a new connection so far (ClientOptions::retries).
  int retries_used() const { return retries_used_; }

 private:
  void connect();
  // For a retry: connect() until a server answers HELLO (ClientOptions::reconnect_window_s).
  void reconnect();
  // Runs one round trip (send, then read the reply) under the retry policy above.
  template <typename RoundTrip>
  auto with_retries(RoundTrip round_trip) -> decltype(round_trip());
  template <typename Reply>
  Reply expect(MessageType type);
  LocalizeReply localize_reply(uint64_t request_id);
  [[noreturn]] void fail(ClientError::Kind kind, const std::string& message);
  // After a failed send: throws the server's ERROR if one is waiting; returns otherwise.
  void rethrow_pending_error();
  // One whole frame by `deadline`, without throwing: the I/O outcome, and kOk or why the
  // header is bad (`frame` is complete only when both are kOk).
  struct FrameRead {
    IoResult io = IoResult::kOk;
    DecodeStatus header = DecodeStatus::kOk;
  };
  FrameRead try_read_frame(Clock::time_point deadline, Frame& frame);
  [[noreturn]] void throw_server_error(const ErrorReply& e) const;

  ClientOptions options_;
  std::string host_;
  uint16_t port_ = 0;
  std::string where_;
  Socket socket_;
  bool broken_ = false;
  int retries_used_ = 0;
};

}  // namespace api
}  // namespace segmatch
