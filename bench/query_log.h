// Per-query figures segmatch-bench collects for one data set (module timings, sizes, accuracy
// against a reference pose) and the table it prints of them.
#pragma once

#include "segmatch/core/localization/localizer.h"

#include <cstddef>
#include <vector>

namespace segmatch::bench {

struct QueryLog {
  std::vector<ModuleTimings> timings;
  std::vector<double> cpu, points, segments, candidates, matches;
  size_t localized = 0, accurate = 0, wrong = 0;

  // truth: T_map_sensor expected; T_query_sensor: the sensor in the query frame. Accurate:
  // within 0.2 m and 1 deg; wrong: off by more than 1 m or 3 deg.
  void add(const LocalizationResult& r, double cpu_used_ms, size_t cloud_points, const Pose3d& T_query_sensor,
           const Pose3d& truth);
  double total_median() const;
  // Median and p90 of every module, CPU time, sizes and the localization counts.
  void print(const char* title) const;
};

}  // namespace segmatch::bench
