// segmatch-bench-server --console-poll: a browser's worth of load on the operator's page (issue
// 36, docs/console.md): the map once, then every period what the page fetches (the answers
// since its cursor, the statistics) and a tile (cached after its first fetch, as a page that
// pans). Plain sockets: the bench needs no HTTP library.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>

namespace segmatch::bench {

class ConsolePoller {
 public:
  ConsolePoller(uint16_t port, double period_s);
  ~ConsolePoller();  // stops and joins
  ConsolePoller(const ConsolePoller&) = delete;
  ConsolePoller& operator=(const ConsolePoller&) = delete;
  uint64_t requests() const { return requests_.load(); }
  uint64_t failures() const { return failures_.load(); }
  uint64_t bytes() const { return bytes_.load(); }

 private:
  void run();
  bool get(const std::string& target, std::string& body);

  uint16_t port_;
  double period_s_;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> requests_{0}, failures_{0}, bytes_{0};
  std::thread thread_;
};

// Runs `level` (one closed-loop level; its queries/s) once to warm up, then 2 x `rounds` times
// alone and with a ConsolePoller on `console_port` each second, in the order ABBA BAAB ... so
// that a drift of the machine weighs on both alike; prints each run, the medians and their
// ratio (and writes them to `json_path` unless empty). Exit code: 1 if an HTTP request failed.
int compare_console_poll(uint16_t console_port, int rounds, const std::string& json_path,
                         const std::function<double()>& level);

}  // namespace segmatch::bench
