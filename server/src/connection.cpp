// One connection: read a frame (header, then payload in bounded chunks), authenticate,
// dispatch, reply, log. Decoding errors that keep the stream in sync are answered with ERROR
// and the connection goes on; the others (bad magic, version, oversize) and authentication
// failures are answered with ERROR and the connection is closed.
#include "server_state.h"

#include "segmatch/server/metrics.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <future>
#include <optional>

#include <sys/socket.h>

namespace segmatch {
namespace server {
namespace {

using api::DecodeStatus;
using api::ErrorCode;
using api::MessageType;

constexpr size_t kReadChunkBytes = 1u << 20;  // payload memory grows only as bytes arrive

// One unit on a gauge of the metrics (in flight, connections) for as long as it lives.
class GaugeHeld {
 public:
  GaugeHeld(Metrics* metrics, void (Metrics::*gauge)(int)) : metrics_(metrics), gauge_(gauge) {
    if (metrics_) (metrics_->*gauge_)(+1);
  }
  ~GaugeHeld() {
    if (metrics_) (metrics_->*gauge_)(-1);
  }
  GaugeHeld(const GaugeHeld&) = delete;
  GaugeHeld& operator=(const GaugeHeld&) = delete;

 private:
  Metrics* metrics_;
  void (Metrics::*gauge_)(int);
};

struct Handled {
  std::vector<uint8_t> reply;
  std::string detail;  // for the log line
  std::string status = "ok";
  bool is_localize = false, localized = false, error = false, timed_out = false;
  uint16_t error_code = 0;  // with error
  std::string error_message;
  bool close_after = false;
  std::optional<Answer> answer;  // a localization's reply, for the operator's page (recent.h)
};

Handled error_reply(ErrorCode code, const std::string& message, bool close_after) {
  Handled h;
  h.reply = api::encode(api::ErrorReply{code, message});
  h.status = "error(" + std::to_string(static_cast<int>(code)) + ": " + message + ")";
  h.error = true;
  h.error_code = static_cast<uint16_t>(code);
  h.error_message = message;
  h.close_after = close_after;
  return h;
}

// No early exit on the first differing byte (the length may leak; the bytes do not).
bool same_token(const std::string& given, const std::string& expected) {
  if (given.size() != expected.size()) return false;
  unsigned char diff = 0;
  for (size_t i = 0; i < given.size(); ++i) diff |= static_cast<unsigned char>(given[i] ^ expected[i]);
  return diff == 0;
}

Handled handle_hello(Server::State& s, const std::vector<uint8_t>& payload, bool& authed) {
  api::HelloRequest hello;
  const DecodeStatus d = api::decode(payload.data(), payload.size(), s.limits, hello);
  if (d != DecodeStatus::kOk) return error_reply(api::error_code_for(d), api::to_string(d), true);
  if (!s.config.token.empty() && !same_token(hello.token, s.config.token))
    return error_reply(ErrorCode::kAuthFailed, "wrong token", true);
  authed = true;
  Handled h;
  h.reply = api::encode(api::HelloOkReply{});
  return h;
}

using TimePoint = std::chrono::steady_clock::time_point;

size_t point_count(const api::LocalizeRequest& r) { return r.points.size(); }
size_t point_count(const api::LocalizeSegmentsRequest& r) {
  size_t n = 0;
  for (const Segment& seg : r.segments) n += seg.points.size();
  return n;
}

std::optional<api::ErrorReply> refuse(const LoadedMap&, const api::LocalizeRequest&) { return std::nullopt; }
std::optional<api::ErrorReply> refuse(const LoadedMap& map, const api::LocalizeSegmentsRequest& r) {
  return refuse_segments(map, r);
}

Outcome localize(const LoadedMap& map, const api::LocalizeRequest& r, const Deadline& deadline) {
  return serve_localize(map, r, deadline);
}
// The segments move into the localizer (the request is not read again).
Outcome localize(const LoadedMap& map, api::LocalizeSegmentsRequest& r, const Deadline& deadline) {
  return serve_localize_segments(map, std::move(r), deadline);
}

// What the operator's page needs of a request, taken before it moves into the worker. The page
// shows every answer's refusal code and method, so the localizer is always asked for them;
// what the client did not ask for is taken out of its reply again (answer_of), which then
// encodes byte for byte as before.
struct Asked {
  Eigen::Vector3d sensor_local = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation_local = Eigen::Quaterniond::Identity();
  bool has_prior = false;
  Pose3d T_map_local_prior = Pose3d::Identity();
  bool refusal_code = false, detail = false;  // what the client asked for
};

template <typename Request>
Asked ask_everything(Request& r, uint32_t prior_bit, uint32_t refusal_bit, uint32_t detail_bit) {
  Asked a;
  a.sensor_local = r.sensor_position_local;
  a.orientation_local = r.sensor_orientation_local;
  a.has_prior = (r.flags & prior_bit) != 0;
  a.T_map_local_prior = r.T_map_local_prior;
  a.refusal_code = (r.flags & refusal_bit) != 0;
  a.detail = (r.flags & detail_bit) != 0;
  r.flags |= refusal_bit | detail_bit;
  return a;
}
Asked ask_everything(api::LocalizeRequest& r) {
  return ask_everything(r, api::kFlagHasPrior, api::kFlagRefusalCode, api::kFlagDetail);
}
Asked ask_everything(api::LocalizeSegmentsRequest& r) {
  return ask_everything(r, api::kSegmentsFlagHasPrior, api::kSegmentsFlagRefusalCode, api::kSegmentsFlagDetail);
}

void set_pose(Answer& a, const Pose3d& T_map_local, const Asked& asked) {
  const Eigen::Vector3d p = T_map_local * asked.sensor_local;
  const Eigen::Matrix3d R = T_map_local.linear() * asked.orientation_local.normalized().toRotationMatrix();
  a.has_pose = true;
  a.x_m = p.x(), a.y_m = p.y(), a.yaw_rad = std::atan2(R(1, 0), R(0, 0));
}

// The page's view of a reply; then the reply as the client asked for it.
Answer answer_of(api::LocalizeReply& reply, const Asked& asked) {
  Answer a;
  a.request_id = reply.request_id;
  a.status = api::to_string(reply.status);
  a.refusal = api::to_string(reply.refusal);
  a.refusal_code = static_cast<uint16_t>(reply.refusal);
  a.reason = reply.reason;
  if (reply.status != api::LocalizeStatus::kNotLocalized)
    set_pose(a, reply.T_map_local, asked);
  else if (asked.has_prior)
    set_pose(a, asked.T_map_local_prior, asked), a.pose_from_prior = true;
  if (reply.detail && reply.detail->estimate) {
    const api::ReplyDetail::Estimate& e = *reply.detail->estimate;
    a.method = api::to_string(static_cast<api::ReplyMethod>(e.method));
    const Eigen::Matrix<double, 6, 6> c = api::covariance_matrix(e.covariance_upper);  // rotation, then position
    if (c(3, 3) > 0.0 && c(4, 4) > 0.0)
      a.has_covariance = true, a.cov_xx_m2 = c(3, 3), a.cov_xy_m2 = c(3, 4), a.cov_yy_m2 = c(4, 4);
  }
  if (!asked.refusal_code) reply.refusal = api::RefusalCode::kNone;
  if (!asked.detail) reply.detail.reset();
  return a;
}

// LOCALIZE or LOCALIZE_SEGMENTS: decode, check, localize on the worker pool, reply.
template <typename Request>
Handled handle_localize(Server::State& s, const std::vector<uint8_t>& payload, TimePoint start) {
  const TimePoint received = std::chrono::steady_clock::now();
  Request request;
  const DecodeStatus d = api::decode(payload.data(), payload.size(), s.limits, request);
  std::optional<api::ErrorReply> refused;
  if (d != DecodeStatus::kOk) refused = api::ErrorReply{api::error_code_for(d), api::to_string(d)};
  // The map this request is answered with, even if a reload replaces it meanwhile.
  const std::shared_ptr<const LoadedMap> map = s.current_map();
  if (!refused) refused = refuse(*map, request);
  if (refused) {
    Handled h = error_reply(refused->code, refused->message, false);
    h.is_localize = true;
    return h;
  }
  Handled h;
  h.is_localize = true;
  char detail[96];
  std::snprintf(detail, sizeof(detail), " id=%llu points=%zu", static_cast<unsigned long long>(request.request_id),
                point_count(request));
  h.detail = detail;
  const Asked asked = ask_everything(request);
  // The localization runs on the bounded worker pool; this connection thread waits for it.
  // The task is shared with the pool: the worker may still be inside it when get() returns.
  // From here on only the worker touches `request`.
  // The deadline counts from the moment the frame was read whole, so a request that waited for
  // a worker past it is answered at once without running (docs/protocol.md 9).
  const Deadline deadline = Deadline::after_s(s.config.request_timeout_s, received);
  auto task = std::make_shared<std::packaged_task<Outcome()>>(
      [map, &request, deadline] { return localize(*map, request, deadline); });
  std::future<Outcome> result = task->get_future();
  const GaugeHeld in_flight(s.config.metrics.get(), &Metrics::in_flight);  // however the wait ends
  s.pool->submit([task] { (*task)(); });
  try {
    Outcome outcome = result.get();
    if (const api::ErrorReply* e = std::get_if<api::ErrorReply>(&outcome)) {
      const std::string keep = h.detail;
      h = error_reply(e->code, e->message, false);
      h.is_localize = true;
      h.timed_out = e->code == ErrorCode::kRequestTimeout;
      h.detail = keep;
      return h;
    }
    api::LocalizeReply& reply = std::get<api::LocalizeReply>(outcome);
    reply.timings.server_total =
        std::chrono::duration<float, std::milli>(std::chrono::steady_clock::now() - start).count();
    h.answer = answer_of(reply, asked);
    h.reply = api::encode(reply);
    h.status = api::to_string(reply.status);
    h.localized = reply.status == api::LocalizeStatus::kLocalized;
    h.detail += " inliers=" + std::to_string(reply.inliers);
  } catch (const std::exception& e) {
    const std::string keep = h.detail;
    h = error_reply(ErrorCode::kInternal, std::string("localization failed: ") + e.what(), false);
    h.is_localize = true;
    h.detail = keep;
  }
  return h;
}

Handled handle_frame(Server::State& s, const api::Header& header, const std::vector<uint8_t>& payload, bool& authed,
                     TimePoint start) {
  const auto type = static_cast<MessageType>(header.type);
  if (type == MessageType::kHello) return handle_hello(s, payload, authed);
  if (!authed) return error_reply(ErrorCode::kAuthRequired, "authenticate with HELLO first", true);
  switch (type) {
    case MessageType::kPing: {
      api::PingRequest ping;
      const DecodeStatus d = api::decode(payload.data(), payload.size(), s.limits, ping);
      if (d != DecodeStatus::kOk) return error_reply(api::error_code_for(d), api::to_string(d), false);
      Handled h;
      h.reply = api::encode(api::PongReply{ping.nonce});
      return h;
    }
    case MessageType::kInfo: {
      api::InfoRequest info;
      const DecodeStatus d = api::decode(payload.data(), payload.size(), s.limits, info);
      if (d != DecodeStatus::kOk) return error_reply(api::error_code_for(d), api::to_string(d), false);
      Handled h;
      h.reply = api::encode(info_of(*s.current_map()));
      return h;
    }
    case MessageType::kLocalize: return handle_localize<api::LocalizeRequest>(s, payload, start);
    case MessageType::kLocalizeSegments: return handle_localize<api::LocalizeSegmentsRequest>(s, payload, start);
    default:
      return error_reply(ErrorCode::kUnexpectedMessage, std::string(api::to_string(type)) + " is not a request", false);
  }
}

// Reads the payload in chunks so a client announcing 64 MiB and sending nothing costs 1 MiB.
api::IoResult read_payload(int fd, size_t n, double timeout_s, std::vector<uint8_t>& payload) {
  const api::Clock::time_point deadline = api::deadline_after(timeout_s);
  payload.clear();
  while (payload.size() < n) {
    const size_t done = payload.size();
    const size_t chunk = std::min(kReadChunkBytes, n - done);
    payload.resize(done + chunk);
    const api::IoResult r = api::read_exact(fd, payload.data() + done, chunk, deadline);
    if (r != api::IoResult::kOk) return r;
  }
  return api::IoResult::kOk;
}

// Closing right after an ERROR while the client is still sending (an oversized frame, say)
// would make the kernel answer the unread bytes with a reset, and a reset can destroy the ERROR
// before the client reads it. So: stop writing, then read and drop what is still coming for a
// bounded time and byte count, and only then close (a "lingering close").
void linger_close(int fd) {
  constexpr double kLingerS = 2.0;
  constexpr size_t kLingerMaxBytes = 256u << 20;
  ::shutdown(fd, SHUT_WR);
  const api::Clock::time_point deadline = api::deadline_after(kLingerS);
  std::vector<uint8_t> sink(64u << 10);
  for (size_t dropped = 0; dropped < kLingerMaxBytes;) {
    const size_t n = api::read_some(fd, sink.data(), sink.size(), deadline);
    if (n == 0) return;
    dropped += n;
  }
}

void log_request(Server::State& s, const std::string& peer, const char* type, const Handled& h, double ms) {
  if (!s.config.log_requests) return;
  char latency[48];
  std::snprintf(latency, sizeof(latency), " latency_ms=%.1f", ms);
  s.log(peer + " " + type + h.detail + " status=" + h.status + latency, h.error ? LogLevel::kWarning : LogLevel::kInfo);
}

// What the metrics count of one answered frame.
void count(Metrics& metrics, const char* type, const Handled& h, double ms) {
  metrics.request(type, h.error ? "error" : h.is_localize ? h.status : "ok", ms / 1000.0, h.is_localize && !h.error);
  if (h.error) metrics.error(h.error_code);
}

// The answer as the page lists it (the reply's part was filled by answer_of).
Answer recent_answer(Handled& h, const std::string& peer, const char* type, double ms) {
  Answer a = h.answer ? std::move(*h.answer) : Answer{};
  h.answer.reset();
  a.peer = peer;
  a.type = type;
  a.latency_ms = ms;
  if (h.error) {
    a.status = "error";
    a.refusal = "NONE";
    a.error_code = h.error_code;
    a.reason = h.error_message;
  }
  return a;
}

}  // namespace

void serve_connection(Server::State& s, api::Socket socket, const std::string& peer) {
  const GaugeHeld open(s.config.metrics.get(), &Metrics::connections);
  bool authed = s.config.token.empty();
  std::vector<uint8_t> payload;
  for (;;) {
    uint8_t header_bytes[api::kHeaderBytes];
    api::IoResult r = api::read_exact(socket.fd(), header_bytes, sizeof(header_bytes),
                                      api::deadline_after(s.config.read_timeout_s), &s.stopping);
    if (r == api::IoResult::kTimeout)
      s.log(peer + " closed: idle for " + std::to_string(s.config.read_timeout_s) + " s");
    if (r != api::IoResult::kOk) return;
    const auto start = std::chrono::steady_clock::now();
    api::Header header;
    const DecodeStatus d = api::decode_header(header_bytes, sizeof(header_bytes), s.limits, header);
    Handled h;
    if (!api::stream_in_sync_after(d)) {
      h = error_reply(api::error_code_for(d), api::to_string(d), true);
    } else {
      r = read_payload(socket.fd(), header.payload_bytes, s.config.read_timeout_s, payload);
      if (r != api::IoResult::kOk) {
        s.log(peer + " closed: frame cut off (" + api::to_string(r) + ")", LogLevel::kWarning);
        return;
      }
      s.stats.received();
      h = d == DecodeStatus::kUnknownType
              ? error_reply(ErrorCode::kUnknownType, "unknown message type " + std::to_string(header.type), !authed)
              : handle_frame(s, header, payload, authed, start);
    }
    // Counted before the reply leaves: a client that reads its reply and then asks for the
    // counters must see its own request in them.
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    s.stats.record(h.is_localize, h.localized, h.error, h.timed_out, ms);
    const char* type_name = d == DecodeStatus::kOk ? api::to_string(static_cast<MessageType>(header.type)) : "FRAME";
    if (h.is_localize) s.recent->add(recent_answer(h, peer, type_name, ms));
    if (s.config.metrics) count(*s.config.metrics, type_name, h, ms);
    r = api::write_all(socket.fd(), h.reply.data(), h.reply.size(), api::deadline_after(s.config.write_timeout_s));
    log_request(s, peer, type_name, h, ms);
    if (r != api::IoResult::kOk) return;
    if (h.close_after) return linger_close(socket.fd());
  }
}

}  // namespace server
}  // namespace segmatch
