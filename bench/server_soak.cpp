#include "server_soak.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

extern char** environ;

namespace segmatch::bench {
namespace {

using Clock = std::chrono::steady_clock;

// A field of /proc/PID/status in MB ("VmRSS", "VmHWM"); 0 when it cannot be read.
double proc_status_mb(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string key;
  double kb = 0;
  while (in >> key) {
    if (key == field + ":" && in >> kb) return kb / 1024.0;
    in.ignore(1 << 16, '\n');
  }
  return 0.0;
}

// segmatch-server on an ephemeral loopback port; its log goes to `log_path`.
class ServerProcess {
 public:
  ServerProcess(const SoakConfig& c, const std::string& log_path) {
    int out[2];
    if (::pipe(out) != 0) throw std::runtime_error("soak: pipe() failed");
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out[1], STDOUT_FILENO);
    posix_spawn_file_actions_addclose(&actions, out[0]);
    posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    std::vector<std::string> args = {c.server_binary, "--map", c.map_path, "--port", "0", "--stats-interval-s", "0"};
    if (c.workers > 0) args.insert(args.end(), {"--workers", std::to_string(c.workers)});
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int rc = posix_spawn(&pid_, c.server_binary.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(out[1]);
    if (rc != 0) {
      ::close(out[0]);
      throw std::runtime_error("soak: cannot start " + c.server_binary + " (give --server-binary)");
    }
    port_ = wait_for_port(out[0], log_path);
    ::close(out[0]);
  }
  ~ServerProcess() {
    if (pid_ > 0) stop();
  }
  uint16_t port() const { return port_; }
  pid_t pid() const { return pid_; }
  // SIGTERM, then the exit status (-1 if it did not exit normally).
  int stop() {
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  }

 private:
  // Reads the server's stdout until "listening on ADDR:PORT" (the map loads first).
  uint16_t wait_for_port(int fd, const std::string& log_path) {
    std::string text;
    const auto give_up = Clock::now() + std::chrono::seconds(300);
    while (Clock::now() < give_up) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 200) > 0) {
        char buffer[256];
        const ssize_t n = ::read(fd, buffer, sizeof buffer);
        if (n <= 0) break;  // the server exited
        text.append(buffer, static_cast<size_t>(n));
        const size_t at = text.find("listening on ");
        const size_t colon = at == std::string::npos ? at : text.find(':', at);
        if (colon != std::string::npos && text.find('\n', colon) != std::string::npos)
          return static_cast<uint16_t>(std::stoi(text.substr(colon + 1)));
      }
    }
    throw std::runtime_error("soak: segmatch-server did not start listening (its log: " + log_path + ")");
  }
  pid_t pid_ = -1;
  uint16_t port_ = 0;
};

}  // namespace

bool SoakResult::passed(const SoakConfig& c) const {
  return errors == 0 && server_exit == 0 && rss_baseline_mb > 0 &&
         rss_end_mb <= rss_baseline_mb * (1.0 + c.max_rss_growth);
}

nlohmann::json SoakResult::to_json() const {
  return {{"answered", answered},
          {"localized", localized},
          {"errors", errors},
          {"seconds", seconds},
          {"rss_baseline_mb", rss_baseline_mb},
          {"rss_end_mb", rss_end_mb},
          {"rss_peak_mb", rss_peak_mb},
          {"server_exit", server_exit}};
}

SoakResult run_soak(const SoakConfig& c, const SoakQuery& query) {
  const std::string log_path = c.map_path + ".server.log";
  ServerProcess server(c, log_path);
  std::printf("soak: segmatch-server pid %d on port %u, %d clients x %d queries, RSS at start %.0f MB\n",
              static_cast<int>(server.pid()), server.port(), c.clients, c.queries_per_client,
              proc_status_mb(server.pid(), "VmRSS"));
  std::fflush(stdout);
  const size_t total = static_cast<size_t>(c.clients) * static_cast<size_t>(c.queries_per_client);
  std::atomic<size_t> done{0}, localized{0}, errors{0};
  std::atomic<double> baseline{0.0};
  std::mutex print;
  const auto start = Clock::now();
  auto seconds = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  auto one_done = [&] {
    const size_t n = ++done;
    if (n == c.baseline_after) baseline = proc_status_mb(server.pid(), "VmRSS");
    if (n % 1000 != 0) return;
    const double s = seconds();
    std::lock_guard<std::mutex> lock(print);
    std::printf("  %zu / %zu queries, %.0f s, ETA %.0f s, server RSS %.1f MB, %zu errors\n", n, total, s,
                s / static_cast<double>(n) * static_cast<double>(total - n), proc_status_mb(server.pid(), "VmRSS"),
                errors.load());
    std::fflush(stdout);
  };
  std::vector<std::thread> threads;
  for (int k = 0; k < c.clients; ++k)
    threads.emplace_back([&, k] {
      api::ClientOptions options;
      options.reply_timeout_s = 600;
      std::unique_ptr<api::Client> client;
      for (int i = 0; i < c.queries_per_client; ++i) {
        try {
          if (!client) client = std::make_unique<api::Client>("127.0.0.1", server.port(), options);
          localized +=
              query(*client, static_cast<size_t>(k), static_cast<size_t>(i)).status == api::LocalizeStatus::kLocalized;
        } catch (const std::exception& e) {
          if (++errors <= 5) {
            std::lock_guard<std::mutex> lock(print);
            std::printf("  client %d query %d: %s\n", k, i, e.what());
          }
          client.reset();  // a new connection for the next query
        }
        one_done();
      }
    });
  for (std::thread& t : threads) t.join();
  SoakResult r;
  r.seconds = seconds();
  r.answered = done - errors;
  r.localized = localized;
  r.errors = errors;
  r.rss_baseline_mb = baseline;
  r.rss_end_mb = proc_status_mb(server.pid(), "VmRSS");
  r.rss_peak_mb = proc_status_mb(server.pid(), "VmHWM");
  r.server_exit = server.stop();
  const double growth = r.rss_baseline_mb > 0 ? 100.0 * (r.rss_end_mb / r.rss_baseline_mb - 1.0) : 0.0;
  std::printf(
      "soak: %zu queries in %.0f s (%.1f queries/s), %zu localized, %zu errors; server RSS after %zu queries "
      "%.1f MB, at the end %.1f MB (%+.1f %%), peak %.1f MB; server exit %d after SIGTERM: %s\n",
      r.answered + r.errors, r.seconds, static_cast<double>(r.answered) / r.seconds, r.localized, r.errors,
      c.baseline_after, r.rss_baseline_mb, r.rss_end_mb, growth, r.rss_peak_mb, r.server_exit,
      r.passed(c) ? "PASS" : "FAIL");
  if (r.passed(c))
    std::remove(log_path.c_str());
  else
    std::printf("soak: the server's log is kept: %s\n", log_path.c_str());
  return r;
}

}  // namespace segmatch::bench
