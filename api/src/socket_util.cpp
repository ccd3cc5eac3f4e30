// Poll-based blocking IO: every wait is a poll() slice of at most 100 ms, so deadlines and
// stop flags are honoured without signals.
#include "segmatch/api/socket_io.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace segmatch {
namespace api {
namespace {

constexpr int kSliceMs = 100;

// Waits for `events` until the deadline or the stop flag; returns poll's revents or 0.
int wait_for(int fd, short events, Clock::time_point deadline, const std::atomic<bool>* stop, bool& stopped) {
  for (;;) {
    if (stop && stop->load()) {
      stopped = true;
      return 0;
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
    if (left <= 0) return 0;
    pollfd p{fd, events, 0};
    const int n = ::poll(&p, 1, static_cast<int>(std::min<int64_t>(left, kSliceMs)));
    if (n > 0) return p.revents;
    if (n < 0 && errno != EINTR) return POLLERR;
  }
}

}  // namespace

Socket& Socket::operator=(Socket&& o) noexcept {
  if (this != &o) {
    close();
    fd_ = o.release();
  }
  return *this;
}

void Socket::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void Socket::shutdown_both() {
  if (fd_ >= 0) ::shutdown(fd_, SHUT_RDWR);
}

const char* to_string(IoResult r) {
  switch (r) {
    case IoResult::kOk: return "ok";
    case IoResult::kTimeout: return "timed out";
    case IoResult::kClosed: return "connection closed by peer";
    case IoResult::kError: return "socket error";
    case IoResult::kStopped: return "stopped";
  }
  return "?";
}

IoResult read_exact(int fd, uint8_t* data, size_t n, Clock::time_point deadline, const std::atomic<bool>* stop) {
  size_t done = 0;
  while (done < n) {
    bool stopped = false;
    const int ev = wait_for(fd, POLLIN, deadline, done == 0 ? stop : nullptr, stopped);
    if (stopped) return IoResult::kStopped;
    if (ev == 0) return IoResult::kTimeout;
    const ssize_t got = ::recv(fd, data + done, n - done, 0);
    if (got == 0) return IoResult::kClosed;
    if (got < 0) {
      if (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) continue;
      return errno == ECONNRESET ? IoResult::kClosed : IoResult::kError;
    }
    done += static_cast<size_t>(got);
  }
  return IoResult::kOk;
}

size_t read_some(int fd, uint8_t* data, size_t n, Clock::time_point deadline) {
  for (;;) {
    bool stopped = false;
    if (wait_for(fd, POLLIN, deadline, nullptr, stopped) == 0) return 0;
    const ssize_t got = ::recv(fd, data, n, 0);
    if (got > 0) return static_cast<size_t>(got);
    if (got < 0 && (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK)) continue;
    return 0;
  }
}

IoResult write_all(int fd, const uint8_t* data, size_t n, Clock::time_point deadline) {
  size_t done = 0;
  while (done < n) {
    bool stopped = false;
    const int ev = wait_for(fd, POLLOUT, deadline, nullptr, stopped);
    if (ev == 0) return IoResult::kTimeout;
    if (ev & (POLLERR | POLLHUP)) return IoResult::kClosed;
    const ssize_t sent = ::send(fd, data + done, n - done, MSG_NOSIGNAL);
    if (sent < 0) {
      if (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK) continue;
      return (errno == EPIPE || errno == ECONNRESET) ? IoResult::kClosed : IoResult::kError;
    }
    done += static_cast<size_t>(sent);
  }
  return IoResult::kOk;
}

namespace {

// Non-blocking connect bounded by the deadline; returns the connected socket or an error text.
Socket try_connect(const addrinfo* ai, Clock::time_point deadline, std::string& error) {
  Socket s(::socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC, ai->ai_protocol));
  if (!s.valid()) {
    error = std::strerror(errno);
    return {};
  }
  const int flags = ::fcntl(s.fd(), F_GETFL, 0);
  ::fcntl(s.fd(), F_SETFL, flags | O_NONBLOCK);
  if (::connect(s.fd(), ai->ai_addr, ai->ai_addrlen) != 0 && errno != EINPROGRESS) {
    error = std::strerror(errno);
    return {};
  }
  bool stopped = false;
  if (wait_for(s.fd(), POLLOUT, deadline, nullptr, stopped) == 0) {
    error = "connect timed out";
    return {};
  }
  int so_error = 0;
  socklen_t len = sizeof(so_error);
  ::getsockopt(s.fd(), SOL_SOCKET, SO_ERROR, &so_error, &len);
  if (so_error != 0) {
    error = std::strerror(so_error);
    return {};
  }
  ::fcntl(s.fd(), F_SETFL, flags);  // back to blocking; every wait goes through poll anyway
  const int one = 1;
  ::setsockopt(s.fd(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));  // small replies go out at once
  return s;
}

}  // namespace

Socket connect_tcp(const std::string& host, uint16_t port, std::chrono::milliseconds timeout) {
  const std::string where = host + ":" + std::to_string(port);
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* list = nullptr;
  const int rc = ::getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &list);
  if (rc != 0) throw std::runtime_error("cannot resolve " + where + ": " + ::gai_strerror(rc));
  const Clock::time_point deadline = Clock::now() + timeout;
  std::string error = "no address";
  for (const addrinfo* ai = list; ai; ai = ai->ai_next) {
    Socket s = try_connect(ai, deadline, error);
    if (s.valid()) {
      ::freeaddrinfo(list);
      return s;
    }
  }
  ::freeaddrinfo(list);
  throw std::runtime_error("cannot connect to " + where + ": " + error);
}

std::string peer_address(int fd) {
  sockaddr_storage addr{};
  socklen_t len = sizeof(addr);
  if (::getpeername(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) return "?";
  char host[INET6_ADDRSTRLEN] = "?";
  uint16_t port = 0;
  if (addr.ss_family == AF_INET) {
    const auto* a = reinterpret_cast<const sockaddr_in*>(&addr);
    ::inet_ntop(AF_INET, &a->sin_addr, host, sizeof(host));
    port = ntohs(a->sin_port);
  } else if (addr.ss_family == AF_INET6) {
    const auto* a = reinterpret_cast<const sockaddr_in6*>(&addr);
    ::inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof(host));
    port = ntohs(a->sin6_port);
  }
  return std::string(host) + ":" + std::to_string(port);
}

}  // namespace api
}  // namespace segmatch
