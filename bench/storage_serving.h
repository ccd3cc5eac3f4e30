// segmatch-bench-storage's "open for serving": server::load_map in a fresh child process (so each
// mode starts from an empty heap), its time and resident memory, then 100 queries answered from
// that map, timed, with the memory after them. Lazy and in-memory runs answer the same queries,
// so their difference is the time lazy point reads add to a query.
#pragma once

#include <segmatch/server/map_service.h>

#include <string>

namespace segmatch {
namespace bench {

struct QueryFigures {
  int queries = 0, localized = 0, correct = 0;  // correct: within 5 cm of the known pose
  double median_ms = 0, p90_ms = 0;
  double pose_sum = 0;                                 // sum of the localized translations: the same answers?
  unsigned long long point_reads = 0, cache_hits = 0;  // lazy mode: LazyPoints' counters
};

struct ServingFigures {
  bool ok = false;
  double open_s = 0, heap_mb = 0, file_mb = 0;  // after the open
  double heap_after_mb = 0, file_after_mb = 0;  // after the queries
  QueryFigures route;                           // a query every 5 m along the map's trajectory (a vehicle driving)
  QueryFigures random;                          // then 100 at random places of the map (every one misses the cache)
};

// Runs in a child process and returns what it measured. With drop_caches the page cache is
// emptied (root; /proc/sys/vm/drop_caches) before the open and again before the queries, so
// both read the map from disk.
ServingFigures open_for_serving(const std::string& path, server::MapPoints mode, bool drop_caches);

// False (and why) when this process cannot drop the page cache.
bool can_drop_caches(std::string* why);

}  // namespace bench
}  // namespace segmatch
