// Raw HTTP/1.1 over a loopback socket for the operator's page tests: the bytes a browser, a
// dashboard or a misbehaving client sends, and what came back (until the server closes or the
// wait ends).
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace segmatch::testing {

struct HttpReply {
  int status = 0;  // 0: nothing parseable came back
  std::string head, body;
  bool closed = false;  // the server closed the connection within the wait
};

class RawHttp {
 public:
  explicit RawHttp(uint16_t port) : fd_(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0)) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd_ < 0 || ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0)
      throw std::runtime_error("cannot connect");
  }
  ~RawHttp() { ::close(fd_); }
  RawHttp(const RawHttp&) = delete;
  RawHttp& operator=(const RawHttp&) = delete;

  bool send(const std::string& bytes) {
    size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::send(fd_, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (n <= 0) return false;
      done += static_cast<size_t>(n);
    }
    return true;
  }
  // Reads until the server closes or `wait_s` passes without a byte.
  HttpReply read(double wait_s) {
    std::string in;
    HttpReply r;
    for (;;) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(wait_s * 1000)) <= 0) break;
      char buf[65536];
      const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n <= 0) {
        r.closed = true;
        break;
      }
      in.append(buf, static_cast<size_t>(n));
    }
    const size_t end = in.find("\r\n\r\n");
    r.head = in.substr(0, end);
    if (end != std::string::npos) r.body = in.substr(end + 4);
    if (in.compare(0, 9, "HTTP/1.1 ") == 0 || in.compare(0, 9, "HTTP/1.0 ") == 0) r.status = std::atoi(in.c_str() + 9);
    return r;
  }

 private:
  int fd_;
};

// One GET on its own connection ("Connection: close"); `headers` end with "\r\n" each.
inline HttpReply http_get(uint16_t port, const std::string& target, const std::string& headers = "",
                          double wait_s = 10.0) {
  RawHttp c(port);
  c.send("GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n" + headers + "\r\n");
  return c.read(wait_s);
}

}  // namespace segmatch::testing
