// segmatch-bench-server --console-poll: a browser's worth of load on the operator's page (issue
// 36, docs/console.md): the map once, then every period what the page fetches (the answers
// since its cursor, the statistics) and a tile (cached after its first fetch, as a page that
// pans). Plain sockets: the bench needs no HTTP library.
#pragma once

#include <atomic>
#include <cstdint>
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

}  // namespace segmatch::bench
