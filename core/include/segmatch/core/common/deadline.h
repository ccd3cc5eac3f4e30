// When a query's work is abandoned: a server bounds every request (--request-timeout-s) so that
// one pathological cloud cannot hold a worker for minutes while the fleet's queries queue behind
// it. Cancellation is cooperative: the localizer looks at the deadline between its stages and
// between segments while describing them (the longest stage on large clouds), so it stops at
// most one stage step late; a stage that finished is never undone.
#pragma once

#include <chrono>

namespace segmatch {

class Deadline {
 public:
  using Clock = std::chrono::steady_clock;

  Deadline() = default;  // never passes
  static Deadline never() { return Deadline(); }
  static Deadline at(Clock::time_point when) {
    Deadline d;
    d.set_ = true;
    d.when_ = when;
    return d;
  }
  // `seconds` from `start`; seconds <= 0 or not finite: never.
  static Deadline after_s(double seconds, Clock::time_point start = Clock::now()) {
    if (!(seconds > 0.0) || seconds > 1e9) return never();
    return at(start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds)));
  }

  bool passed() const { return set_ && Clock::now() >= when_; }
  bool is_set() const { return set_; }
  Clock::time_point when() const { return when_; }

 private:
  bool set_ = false;
  Clock::time_point when_{};
};

}  // namespace segmatch
