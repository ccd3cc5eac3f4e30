#include "segmatch/api/client.h"

#include <algorithm>
#include <thread>

namespace segmatch {
namespace api {

Client::Client(const std::string& host, uint16_t port, const ClientOptions& options)
    : options_(options), host_(host), port_(port), where_(host + ":" + std::to_string(port)) {
  if (options_.retries < 0) throw std::invalid_argument("ClientOptions::retries must be >= 0");
  if (!(options_.reconnect_window_s >= 0))
    throw std::invalid_argument("ClientOptions::reconnect_window_s must be >= 0");
  connect();
}

void Client::connect() {
  try {
    socket_ =
        connect_tcp(host_, port_, std::chrono::milliseconds(static_cast<int64_t>(options_.connect_timeout_s * 1000)));
  } catch (const std::exception& e) {
    throw ClientError(ClientError::Kind::kConnect, e.what());
  }
  broken_ = false;
  if (!options_.token.empty()) {
    send_raw(encode(HelloRequest{options_.token}));
    expect<HelloOkReply>(MessageType::kHelloOk);
  }
}

void Client::reconnect() {
  const auto give_up = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                          std::chrono::duration<double>(options_.reconnect_window_s));
  std::chrono::milliseconds pause(50);
  for (;;) {
    try {
      socket_ =
          connect_tcp(host_, port_, std::chrono::milliseconds(static_cast<int64_t>(options_.connect_timeout_s * 1000)));
      broken_ = false;
      send_raw(encode(HelloRequest{options_.token}));
      expect<HelloOkReply>(MessageType::kHelloOk);
      return;
    } catch (const ClientError& e) {
      // An ERROR (a wrong token), a stalled or garbled handshake: a live server said no.
      if (e.kind != ClientError::Kind::kClosed || Clock::now() + pause > give_up) throw;
    } catch (const std::exception& e) {
      if (Clock::now() + pause > give_up) throw ClientError(ClientError::Kind::kConnect, e.what());
    }
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::milliseconds(1000));
  }
}

template <typename RoundTrip>
auto Client::with_retries(RoundTrip round_trip) -> decltype(round_trip()) {
  for (int attempt = 0;; ++attempt) {
    try {
      if (broken_ && attempt == 0 && options_.retries > 0) {  // broken by an earlier call
        ++retries_used_;
        reconnect();
      }
      return round_trip();
    } catch (const ClientError& e) {
      if (e.kind != ClientError::Kind::kClosed || attempt >= options_.retries) throw;
      ++retries_used_;
      reconnect();
    }
  }
}

void Client::fail(ClientError::Kind kind, const std::string& message) {
  broken_ = true;
  socket_.close();
  throw ClientError(kind, where_ + ": " + message);
}

void Client::send_raw(const std::vector<uint8_t>& bytes) {
  if (broken_) throw ClientError(ClientError::Kind::kClosed, where_ + ": connection is closed");
  const IoResult r = write_all(socket_.fd(), bytes.data(), bytes.size(), deadline_after(options_.send_timeout_s));
  if (r == IoResult::kTimeout) fail(ClientError::Kind::kTimeout, "send timed out");
  if (r != IoResult::kOk) {
    // A server that refuses a request before reading all of it (too large, bad header) replies
    // with ERROR and closes: that ERROR, when it made it here, says more than "send failed".
    rethrow_pending_error();
    fail(ClientError::Kind::kClosed, std::string("send failed: ") + to_string(r));
  }
}

void Client::rethrow_pending_error() {
  Frame f;
  const FrameRead r = try_read_frame(deadline_after(0.5), f);
  if (r.io != IoResult::kOk || r.header != DecodeStatus::kOk ||
      f.header.type != static_cast<uint16_t>(MessageType::kError))
    return;
  ErrorReply e;
  if (decode(f.payload.data(), f.payload.size(), options_.limits, e) != DecodeStatus::kOk) return;
  broken_ = true;
  socket_.close();
  throw_server_error(e);
}

Client::FrameRead Client::try_read_frame(Clock::time_point deadline, Frame& f) {
  FrameRead r;
  uint8_t header[kHeaderBytes];
  if ((r.io = read_exact(socket_.fd(), header, kHeaderBytes, deadline)) != IoResult::kOk) return r;
  if ((r.header = decode_header(header, kHeaderBytes, options_.limits, f.header)) != DecodeStatus::kOk) return r;
  f.payload.resize(f.header.payload_bytes);
  r.io = read_exact(socket_.fd(), f.payload.data(), f.payload.size(), deadline);
  return r;
}

void Client::throw_server_error(const ErrorReply& e) const {
  throw ClientError(ClientError::Kind::kServer,
                    where_ + ": server error " + std::to_string(static_cast<int>(e.code)) + ": " + e.message, e.code);
}

Frame Client::read_frame() {
  if (broken_) throw ClientError(ClientError::Kind::kClosed, where_ + ": connection is closed");
  Frame f;
  const FrameRead r = try_read_frame(deadline_after(options_.reply_timeout_s), f);
  if (r.io == IoResult::kTimeout)
    fail(ClientError::Kind::kTimeout, "no reply within " + std::to_string(options_.reply_timeout_s) + " s");
  if (r.io != IoResult::kOk) fail(ClientError::Kind::kClosed, std::string("reading the reply: ") + to_string(r.io));
  if (r.header != DecodeStatus::kOk)
    fail(ClientError::Kind::kProtocol, std::string("bad reply header: ") + to_string(r.header));
  return f;
}

template <typename Reply>
Reply Client::expect(MessageType type) {
  const Frame f = read_frame();
  if (f.header.type == static_cast<uint16_t>(MessageType::kError)) {
    ErrorReply e;
    if (decode(f.payload.data(), f.payload.size(), options_.limits, e) != DecodeStatus::kOk)
      fail(ClientError::Kind::kProtocol, "undecodable ERROR reply");
    throw_server_error(e);
  }
  if (f.header.type != static_cast<uint16_t>(type))
    fail(ClientError::Kind::kProtocol,
         std::string("expected ") + to_string(type) + ", got type " + std::to_string(f.header.type));
  Reply reply;
  const DecodeStatus s = decode(f.payload.data(), f.payload.size(), options_.limits, reply);
  if (s != DecodeStatus::kOk)
    fail(ClientError::Kind::kProtocol, std::string("bad ") + to_string(type) + ": " + to_string(s));
  return reply;
}

uint64_t Client::ping(uint64_t nonce) {
  return with_retries([&] {
    send_raw(encode(PingRequest{nonce}));
    const PongReply pong = expect<PongReply>(MessageType::kPong);
    if (pong.nonce != nonce) fail(ClientError::Kind::kProtocol, "PONG nonce differs from the PING's");
    return pong.nonce;
  });
}

InfoReply Client::info() {
  return with_retries([&] {
    send_raw(encode(InfoRequest{}));
    return expect<InfoReply>(MessageType::kInfoReply);
  });
}

LocalizeReply Client::localize_reply(uint64_t request_id) {
  LocalizeReply reply = expect<LocalizeReply>(MessageType::kLocalizeReply);
  if (reply.request_id != request_id)
    fail(ClientError::Kind::kProtocol,
         "reply for request " + std::to_string(reply.request_id) + ", expected " + std::to_string(request_id));
  return reply;
}

LocalizeReply Client::localize(const LocalizeRequest& request) {
  const std::vector<uint8_t> bytes = encode(request);
  return with_retries([&] {
    send_raw(bytes);
    return localize_reply(request.request_id);
  });
}

LocalizeReply Client::localize_segments(const LocalizeSegmentsRequest& request) {
  const std::vector<uint8_t> bytes = encode(request);
  return with_retries([&] {
    send_raw(bytes);
    return localize_reply(request.request_id);
  });
}

}  // namespace api
}  // namespace segmatch
