#include "console_poller.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <vector>

namespace segmatch::bench {

ConsolePoller::ConsolePoller(uint16_t port, double period_s) : port_(port), period_s_(period_s) {
  thread_ = std::thread([this] { run(); });
}

ConsolePoller::~ConsolePoller() {
  stop_ = true;
  thread_.join();
}

// One GET on its own connection; true on a 200 whose body arrived whole (the server closes).
bool ConsolePoller::get(const std::string& target, std::string& body) {
  ++requests_;
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port_);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  std::string in;
  if (fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0) {
    const std::string request = "GET " + target + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
    if (::send(fd, request.data(), request.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(request.size())) {
      char buf[65536];
      for (pollfd p{fd, POLLIN, 0}; ::poll(&p, 1, 10000) > 0;) {
        const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
        if (n <= 0) break;
        in.append(buf, static_cast<size_t>(n));
      }
    }
  }
  if (fd >= 0) ::close(fd);
  bytes_ += in.size();
  const size_t end = in.find("\r\n\r\n");
  if (in.compare(0, 12, "HTTP/1.1 200") != 0 || end == std::string::npos) {
    ++failures_;
    return false;
  }
  body = in.substr(end + 4);
  return true;
}

void ConsolePoller::run() {
  std::string body;
  get("/", body);
  get("/app.js", body);
  get("/api/map", body);
  uint64_t cursor = 0;
  for (int round = 0; !stop_; ++round) {
    const auto next = std::chrono::steady_clock::now() + std::chrono::duration<double>(period_s_);
    if (get("/api/answers?since=" + std::to_string(cursor), body)) {
      // The reply's own cursor is its last "cursor" key (keys in name order: "answers" first).
      const size_t at = body.rfind("\"cursor\":");
      if (at != std::string::npos) cursor = std::strtoull(body.c_str() + at + 9, nullptr, 10);
    }
    get("/api/stats", body);
    get("/api/tiles/4/" + std::to_string(round % 4 - 2) + "/" + std::to_string(round / 4 % 4 - 2), body);
    while (!stop_ && std::chrono::steady_clock::now() < next)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v.size() % 2 ? v[v.size() / 2] : (v[v.size() / 2 - 1] + v[v.size() / 2]) / 2;
}

}  // namespace

int compare_console_poll(uint16_t console_port, int rounds, const std::string& json_path,
                         const std::function<double()>& level) {
  std::printf("  warm-up:");  // the first run fills the point cache: counted in neither
  level();
  std::vector<double> without, with;
  uint64_t polls = 0, failures = 0;
  for (int run = 0; run < 2 * rounds; ++run) {
    const bool polled = run % 4 == 1 || run % 4 == 2;
    std::printf("%s", polled ? "  polled:" : "  alone: ");
    if (!polled) {
      without.push_back(level());
      continue;
    }
    const ConsolePoller poller(console_port, 1.0);
    with.push_back(level());
    polls += poller.requests(), failures += poller.failures();
  }
  const double a = median(without), b = median(with);
  std::printf(
      "console poll: median %.3f queries/s without, %.3f with the page polled every second: ratio %.3f "
      "(%llu HTTP requests, %llu failed)\n",
      a, b, b / a, static_cast<unsigned long long>(polls), static_cast<unsigned long long>(failures));
  if (!json_path.empty())
    std::ofstream(json_path) << nlohmann::json{{"console_poll",
                                                {{"without_qps", without},
                                                 {"with_qps", with},
                                                 {"median_without_qps", a},
                                                 {"median_with_qps", b},
                                                 {"ratio", b / a}}}}
                                    .dump(2)
                             << "\n";
  return failures == 0 ? 0 : 1;
}

}  // namespace segmatch::bench
