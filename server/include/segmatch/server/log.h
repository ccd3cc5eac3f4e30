// segmatch-server's log lines: "YYYY-MM-DDThh:mm:ss.sssZ INFO text", an ISO-8601 UTC timestamp
// to the millisecond and a level, so that journald, Kubernetes and log shippers need no parser
// of their own.
#pragma once

#include <chrono>
#include <string>

namespace segmatch {
namespace server {

enum class LogLevel { kInfo, kWarning, kError };
const char* to_string(LogLevel level);  // "INFO", "WARN", "ERROR"

std::string format_log_line(LogLevel level, const std::string& text,
                            std::chrono::system_clock::time_point when = std::chrono::system_clock::now());

// One whole line on stderr, never interleaved with another thread's.
void log_to_stderr(LogLevel level, const std::string& text);

}  // namespace server
}  // namespace segmatch
