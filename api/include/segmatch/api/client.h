// Blocking TCP client of segmatch-server. One Client is one connection, used from one thread
// at a time. Every failure throws ClientError saying what went wrong; a server ERROR reply
// carries the server's code and message.
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

  // After a timeout, a closed connection or an undecodable reply the byte stream is lost:
  // every later call throws kClosed. A server ERROR leaves the connection usable.
  bool broken() const { return broken_; }
  void close() { socket_.close(); broken_ = true; }

 private:
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
  std::string where_;
  Socket socket_;
  bool broken_ = false;
};

}  // namespace api
}  // namespace segmatch
