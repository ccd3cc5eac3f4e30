#include "segmatch/cli/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace segmatch::cli {
namespace {
constexpr double kTtyPeriodS = 0.2;  // redraw rate on a terminal
constexpr double kLogPeriodS = 5.0;  // one line every few seconds in logs
constexpr int kBarWidth = 30;

double seconds_between(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}
}  // namespace

Progress::Progress(std::string label, size_t total, std::string unit, std::FILE* out)
    : label_(std::move(label)),
      total_(total),
      unit_(std::move(unit)),
      out_(out),
      tty_(out != nullptr && isatty(fileno(out))),
      start_(std::chrono::steady_clock::now()),
      last_print_(start_) {}

Progress::~Progress() { finish(); }

std::string Progress::format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  char buf[64];
  const long s = std::lround(seconds);
  if (s < 60) {
    std::snprintf(buf, sizeof buf, "%ld s", s);
  } else if (s < 3600) {
    std::snprintf(buf, sizeof buf, "%ld min %02ld s", s / 60, s % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%ld h %02ld min", s / 3600, (s % 3600) / 60);
  }
  return buf;
}

void Progress::update(size_t done) {
  if (finished_) return;
  done_ = std::min(std::max(done, done_), total_);
  const auto now = std::chrono::steady_clock::now();
  const double period = tty_ ? kTtyPeriodS : kLogPeriodS;
  if (done_ == total_) {
    finish();
  } else if (seconds_between(last_print_, now) >= period) {
    last_print_ = now;
    print(false);
  }
}

void Progress::finish() {
  if (finished_) return;
  finished_ = true;
  print(true);
}

void Progress::print(bool final_line) {
  if (out_ == nullptr) return;
  const double elapsed = seconds_between(start_, std::chrono::steady_clock::now());
  const double rate = elapsed > 0 ? static_cast<double>(done_) / elapsed : 0.0;
  const double fraction = total_ > 0 ? static_cast<double>(done_) / total_ : 1.0;
  char tail[160];
  if (final_line) {
    std::snprintf(tail, sizeof tail, "%zu/%zu %s in %s (%.1f %s/s)", done_, total_, unit_.c_str(),
                  format_duration(elapsed).c_str(), rate, unit_.c_str());
  } else {
    const double eta = rate > 0 ? (total_ - done_) / rate : NAN;
    std::snprintf(tail, sizeof tail, "%zu/%zu %s %3.0f%%  %.1f %s/s  ETA %s", done_, total_, unit_.c_str(),
                  100.0 * fraction, rate, unit_.c_str(), format_duration(eta).c_str());
  }
  if (tty_) {
    const int filled = static_cast<int>(std::round(fraction * kBarWidth));
    std::string bar(static_cast<size_t>(filled), '#');
    bar.resize(kBarWidth, '.');
    std::fprintf(out_, "\r\033[K[%s] [%s] %s%s", label_.c_str(), bar.c_str(), tail, final_line ? "\n" : "");
  } else {
    std::fprintf(out_, "[%s] %s\n", label_.c_str(), tail);
  }
  std::fflush(out_);
}

}  // namespace segmatch::cli
