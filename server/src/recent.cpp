#include "segmatch/server/recent.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace segmatch {
namespace server {
namespace {

double unix_now_s() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Nearest-rank percentile of a copy (the window is at most a few thousand values).
double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1);
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

Recent::Recent(size_t capacity, size_t latency_window) : ring_(capacity), latencies_ms_(latency_window) {
  if (capacity == 0 || latency_window == 0) throw std::invalid_argument("Recent needs a capacity and a latency window");
  second_of_.fill(-1);
}

void Recent::add(Answer a) {
  a.unix_time_s = unix_now_s();
  const auto second = static_cast<int64_t>(std::floor(a.unix_time_s));
  std::lock_guard<std::mutex> lock(mutex_);
  a.cursor = ++last_cursor_;
  RecentStats& t = totals_;
  ++t.answered;
  ++t.by_type_status[a.type + "/" + a.status];
  if (a.status == "error") {
    ++t.errors[a.error_code];
  } else {
    if (a.status != "localized") ++t.refusals[a.refusal];
    latencies_ms_[latency_count_++ % latencies_ms_.size()] = a.latency_ms;
  }
  const size_t slot = static_cast<size_t>(second % static_cast<int64_t>(per_second_.size()));
  if (second_of_[slot] != second) second_of_[slot] = second, per_second_[slot] = 0;
  ++per_second_[slot];
  ring_[(a.cursor - 1) % ring_.size()] = std::move(a);
}

std::vector<Answer> Recent::since(uint64_t cursor, size_t max_answers, uint64_t& next_cursor, uint64_t& missed) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const uint64_t oldest = last_cursor_ >= ring_.size() ? last_cursor_ - ring_.size() + 1 : 1;
  // A cursor from the future (a restarted server) starts over.
  if (cursor > last_cursor_) cursor = 0;
  const uint64_t first = std::max(cursor + 1, oldest);
  missed = first - (cursor + 1);
  std::vector<Answer> out;
  for (uint64_t c = first; c <= last_cursor_ && out.size() < max_answers; ++c)
    out.push_back(ring_[(c - 1) % ring_.size()]);
  next_cursor = out.empty() ? std::max(cursor, first - 1) : out.back().cursor;
  return out;
}

RecentStats Recent::stats() const {
  const auto now = static_cast<int64_t>(std::floor(unix_now_s()));
  std::lock_guard<std::mutex> lock(mutex_);
  RecentStats s = totals_;
  uint64_t in_window = 0;
  for (size_t i = 0; i < per_second_.size(); ++i)
    if (second_of_[i] >= now - kRateWindowS && second_of_[i] < now) in_window += per_second_[i];
  s.rate_window_s = kRateWindowS;
  s.rate_per_s = static_cast<double>(in_window) / kRateWindowS;
  const size_t n = std::min(latency_count_, latencies_ms_.size());
  const std::vector<double> window(latencies_ms_.begin(), latencies_ms_.begin() + static_cast<std::ptrdiff_t>(n));
  s.latency_samples = n;
  s.p50_ms = percentile(window, 0.50), s.p90_ms = percentile(window, 0.90), s.p99_ms = percentile(window, 0.99);
  return s;
}

}  // namespace server
}  // namespace segmatch
