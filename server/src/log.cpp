#include "segmatch/server/log.h"

#include <time.h>

#include <cstdio>
#include <iostream>
#include <mutex>

namespace segmatch {
namespace server {

const char* to_string(LogLevel level) {
  switch (level) {
    case LogLevel::kInfo: return "INFO";
    case LogLevel::kWarning: return "WARN";
    case LogLevel::kError: return "ERROR";
  }
  return "INFO";
}

std::string format_log_line(LogLevel level, const std::string& text, std::chrono::system_clock::time_point when) {
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(when.time_since_epoch()).count();
  const time_t seconds = static_cast<time_t>(ms / 1000);
  tm utc{};
  gmtime_r(&seconds, &utc);
  char stamp[48];
  std::snprintf(stamp, sizeof(stamp), "%04d-%02d-%02dT%02d:%02d:%02d.%03dZ", utc.tm_year + 1900, utc.tm_mon + 1,
                utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec, static_cast<int>(ms % 1000));
  return std::string(stamp) + " " + to_string(level) + " " + text;
}

void log_to_stderr(LogLevel level, const std::string& text) {
  const std::string line = format_log_line(level, text) + "\n";
  static std::mutex mutex;
  std::lock_guard<std::mutex> lock(mutex);
  std::cerr << line << std::flush;
}

}  // namespace server
}  // namespace segmatch
