// segmatch-bench-server --soak: segmatch-server as its own process, many clients sending
// queries back to back for a long run, the server's resident memory watched.
#pragma once

#include <segmatch/api/client.h>

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <string>

namespace segmatch::bench {

struct SoakConfig {
  std::string server_binary;  // segmatch-server
  std::string map_path;
  int workers = 0;  // the server's --workers (0: its default, the cores)
  int clients = 16;
  int queries_per_client = 1000;
  size_t baseline_after = 100;   // queries answered in total when the baseline RSS is taken
  double max_rss_growth = 0.05;  // the end RSS may exceed the baseline by this fraction
};

// Query i of a client (i counts from 0 for every client): sends it and returns the reply.
using SoakQuery = std::function<api::LocalizeReply(api::Client&, size_t client, size_t i)>;

struct SoakResult {
  size_t answered = 0, localized = 0, errors = 0;
  double seconds = 0, rss_baseline_mb = 0, rss_end_mb = 0, rss_peak_mb = 0;
  int server_exit = -1;  // the server's exit status after SIGTERM (0: clean)
  bool passed(const SoakConfig& c) const;
  nlohmann::json to_json() const;
};

// Starts the server, runs the clients, stops the server with SIGTERM. Prints progress with an
// ETA and the figures. Throws std::runtime_error when the server cannot be started.
SoakResult run_soak(const SoakConfig& config, const SoakQuery& query);

}  // namespace segmatch::bench
