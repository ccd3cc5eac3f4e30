// Progress reporting for long runs: a one-line bar with rate and ETA on a terminal, and
// plain per-step lines (at most one every few seconds) when stderr is a log or a CI pipe.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdio>
#include <string>

namespace segmatch::cli {

class Progress {
 public:
  // label: what is counted ("seq 00"), unit: what one step is ("scans").
  Progress(std::string label, size_t total, std::string unit, std::FILE* out = stderr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Reports that `done` steps out of total are complete (monotonic).
  void update(size_t done);
  void advance(size_t steps = 1) { update(done_ + steps); }
  // Prints the final line (total time and rate); called by the destructor if not yet done.
  void finish();

  // Formats seconds as "12 s", "3 min 05 s" or "1 h 02 min".
  static std::string format_duration(double seconds);

 private:
  void print(bool final_line);

  std::string label_;
  size_t total_;
  std::string unit_;
  std::FILE* out_;
  bool tty_;
  bool finished_ = false;
  size_t done_ = 0;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_print_;
};

}  // namespace segmatch::cli
