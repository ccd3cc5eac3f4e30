// The server's recent answers and the statistics of its localizations, for the operator's page
// (docs/console.md): a fixed-size ring of the last answers (what the page draws per
// client) and counts kept since start (what it tabulates). Memory is bounded whatever the
// traffic: `capacity` answers, `latency_window` latencies and one slot per second of the rate
// window. Filled by the connection threads as replies are produced; read by the HTTP threads.
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace segmatch {
namespace server {

// One LOCALIZE or LOCALIZE_SEGMENTS answered (a reply or an ERROR).
struct Answer {
  uint64_t cursor = 0;       // 1, 2, ... in answer order (set by Recent::add)
  double unix_time_s = 0.0;  // when the reply was ready (set by Recent::add)
  std::string peer;          // "ADDR:PORT" of the connection
  std::string type;          // LOCALIZE or LOCALIZE_SEGMENTS
  uint64_t request_id = 0;
  std::string status;   // localized, not_localized, outside_prior or error
  std::string refusal;  // api::RefusalCode's name (NONE when localized or an ERROR)
  uint16_t refusal_code = 0;
  std::string reason;       // the reply's reason or the ERROR's message
  uint16_t error_code = 0;  // with status error
  std::string method;       // segments, registration, surfaces, places ("" for an ERROR)
  // The sensor in the map frame: where the answer puts it (localized, outside_prior) or, for a
  // refusal with a prior, where the prior puts it (pose_from_prior).
  bool has_pose = false, pose_from_prior = false;
  double x_m = 0.0, y_m = 0.0, yaw_rad = 0.0;
  // The horizontal block of the position covariance (m^2), when the localizer estimated one.
  bool has_covariance = false;
  double cov_xx_m2 = 0.0, cov_xy_m2 = 0.0, cov_yy_m2 = 0.0;
  double latency_ms = 0.0;  // frame received to reply ready
};

struct RecentStats {
  uint64_t answered = 0;  // every Answer added since start
  // Keys "TYPE/status" as segmatch_requests_total{type,status} counts them.
  std::map<std::string, uint64_t> by_type_status;
  std::map<std::string, uint64_t> refusals;  // by api::RefusalCode name, refusals only
  std::map<uint16_t, uint64_t> errors;       // by ERROR code
  // Answers per second over the last `rate_window_s` whole seconds.
  double rate_per_s = 0.0;
  int rate_window_s = 0;
  // Latencies of the last `latency_samples` replies that were not ERRORs (as the Prometheus
  // histogram counts them); 0 when none.
  size_t latency_samples = 0;
  double p50_ms = 0.0, p90_ms = 0.0, p99_ms = 0.0;
};

class Recent {
 public:
  static constexpr int kRateWindowS = 10;
  explicit Recent(size_t capacity = 4096, size_t latency_window = 1024);
  Recent(const Recent&) = delete;
  Recent& operator=(const Recent&) = delete;

  void add(Answer answer);
  // The answers after `cursor` still in the ring, oldest first, at most `max_answers` (the
  // oldest of them); `next_cursor` is what to ask with next time. A cursor older than the ring
  // gets what the ring holds (the page has missed some: `missed` says how many).
  std::vector<Answer> since(uint64_t cursor, size_t max_answers, uint64_t& next_cursor, uint64_t& missed) const;
  RecentStats stats() const;
  size_t capacity() const { return ring_.size(); }

 private:
  mutable std::mutex mutex_;
  std::vector<Answer> ring_;  // slot (cursor - 1) % capacity
  uint64_t last_cursor_ = 0;
  std::vector<double> latencies_ms_;  // ring of latency_window
  size_t latency_count_ = 0;
  std::array<uint64_t, kRateWindowS + 2> per_second_{};  // by unix second % size
  std::array<int64_t, kRateWindowS + 2> second_of_{};
  RecentStats totals_;
};

}  // namespace server
}  // namespace segmatch
