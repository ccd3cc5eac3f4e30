// What a replayed query knows before it is sent: nothing (global), the Tracker's
// last fix (--track), or a GNSS-like guess (--gnss-sigma-m); and the same-run comparison of a
// query with and without its prior (--compare-global).
#pragma once

#include "segmatch/api/tracker.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/eval/localization_run.h"

#include <functional>
#include <string>
#include <vector>

namespace segmatch {
namespace eval {

class QueryPriors {
 public:
  // truth: T_map_sensor per scan of the query sequence (the GNSS guesses are drawn around it).
  QueryPriors(const LocalizationRunConfig& config, const Poses& truth);
  // Sets the request's prior (if any); returns the mode: "global", "tracked" or "gnss".
  std::string prepare(api::LocalizeRequest& request, const io::ReplayQuery& q);
  // True when the tracker's gate rejected a LOCALIZED reply (api::Tracker).
  bool update(const api::LocalizeReply& reply, const io::ReplayQuery& q);

 private:
  const LocalizationRunConfig& config_;
  const Poses& truth_;
  api::Tracker tracker_;
  Rng gnss_rng_;
};

// Server time and retrieve + classify + verify of the queries sent with a prior, and of the
// same queries sent again without it.
struct PriorComparison {
  std::vector<double> prior_server_ms, prior_match_ms, global_server_ms, global_match_ms;
  void add(const api::LocalizeRequest& request, const api::LocalizeReply& reply, const LocalizeFn& localize);
  void write_to(LocalizationRun& run) const;
};

}  // namespace eval
}  // namespace segmatch
