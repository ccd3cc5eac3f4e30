// Blocking POSIX socket helpers with poll()-based timeouts, shared by the client and the
// server. No call blocks longer than its deadline (plus one 100 ms poll slice).
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <string>

namespace segmatch {
namespace api {

using Clock = std::chrono::steady_clock;

// Owns a file descriptor; closes it on destruction.
class Socket {
 public:
  Socket() = default;
  explicit Socket(int fd) : fd_(fd) {}
  Socket(Socket&& o) noexcept : fd_(o.release()) {}
  Socket& operator=(Socket&& o) noexcept;
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;
  ~Socket() { close(); }
  int fd() const { return fd_; }
  bool valid() const { return fd_ >= 0; }
  int release() {
    const int fd = fd_;
    fd_ = -1;
    return fd;
  }
  void close();
  // Stops further sends and receives (wakes a thread blocked in poll on this socket).
  void shutdown_both();

 private:
  int fd_ = -1;
};

enum class IoResult { kOk, kTimeout, kClosed, kError, kStopped };
const char* to_string(IoResult r);

// Reads exactly n bytes before `deadline`. kClosed when the peer closed (even mid-way).
// When `stop` is given and becomes true while nothing of the n bytes has arrived yet, returns
// kStopped (a server shutting down leaves idle connections, never half-read frames).
IoResult read_exact(int fd, uint8_t* data, size_t n, Clock::time_point deadline,
                    const std::atomic<bool>* stop = nullptr);
// Reads whatever has arrived, up to n bytes, waiting until `deadline` for the first byte.
// Returns the count; 0 means the peer closed, the deadline passed or the socket failed.
size_t read_some(int fd, uint8_t* data, size_t n, Clock::time_point deadline);
// Writes all n bytes before `deadline` (MSG_NOSIGNAL: a dead peer gives kClosed, no SIGPIPE).
IoResult write_all(int fd, const uint8_t* data, size_t n, Clock::time_point deadline);

// TCP connection to host:port (name or numeric address) within timeout. Throws
// std::runtime_error naming host, port and the cause.
Socket connect_tcp(const std::string& host, uint16_t port, std::chrono::milliseconds timeout);

// "ADDR:PORT" of the peer (or "?" if unknown).
std::string peer_address(int fd);

inline Clock::time_point deadline_after(double seconds) {
  return Clock::now() + std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
}

}  // namespace api
}  // namespace segmatch
