// Which local clouds of the simulated revisit segmatch-bench queries: on mapped streets (within
// 5 m of the first traversal), after a warm-up, spread evenly, and which of them the PCL stages
// are timed on.
#pragma once

#include "segmatch/sim/city.h"
#include "segmatch/sim/local_clouds.h"

#include <cstddef>
#include <cstdint>
#include <set>
#include <vector>

namespace segmatch::bench {

// Queries only after this much driving (the simulator's and the end-to-end test's warm-up).
constexpr double kQueryWarmupM = 30.0;

struct QueryPlan {
  sim::LocalCloudSchedule schedule;  // the local clouds handed out along the revisit
  std::set<size_t> selected;         // frames queried
  std::set<size_t> compared;         // frames also timed with PCL
};

// One local cloud every 10 m (as the end-to-end test), closer on short revisits so that there
// are about 1.5 candidates per requested query; `queries` of them spread evenly, `pcl_clouds`
// of those compared. Prints what it chose.
QueryPlan plan_queries(const sim::City& city, int queries, int pcl_clouds, uint64_t seed, int threads);

// n indices spread evenly over 0..count-1 (all of them if count <= n).
std::vector<size_t> spread(size_t count, size_t n);

// Frames at which sim::for_each_local_cloud hands out a local cloud (mirrors its schedule).
std::vector<size_t> scheduled_frames(const sim::Traversal& t, const LocalCloudConfig& lc,
                                     const sim::LocalCloudSchedule& s);

}  // namespace segmatch::bench
