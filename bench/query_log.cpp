// See query_log.h.
#include "query_log.h"

#include "pcl_stages.h"  // median, quantile

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace segmatch::bench {
namespace {

struct ModuleField {
  const char* name;
  double ModuleTimings::*ms;
};
const ModuleField kModules[] = {{"voxel", &ModuleTimings::voxel_ms},       {"ground", &ModuleTimings::ground_ms},
                                {"segment", &ModuleTimings::segment_ms},   {"describe", &ModuleTimings::describe_ms},
                                {"retrieve", &ModuleTimings::retrieve_ms}, {"classify", &ModuleTimings::classify_ms},
                                {"verify", &ModuleTimings::verify_ms},     {"refine", &ModuleTimings::refine_ms},
                                {"total", &ModuleTimings::total_ms}};

}  // namespace

void QueryLog::add(const LocalizationResult& r, double cpu_used_ms, size_t cloud_points, const Pose3d& T_query_sensor,
                   const Pose3d& truth) {
  timings.push_back(r.timings);
  cpu.push_back(cpu_used_ms);
  points.push_back(static_cast<double>(cloud_points));
  segments.push_back(static_cast<double>(r.query_segments));
  candidates.push_back(static_cast<double>(r.candidates));
  matches.push_back(static_cast<double>(r.matches));
  if (!r.localized()) return;
  ++localized;
  const Pose3d T_map_sensor = r.T_map_query * T_query_sensor;
  const double err_m = (T_map_sensor.translation() - truth.translation()).norm();
  const double err_deg = Eigen::AngleAxisd(T_map_sensor.linear().transpose() * truth.linear()).angle() * 180.0 / M_PI;
  accurate += err_m <= 0.2 && err_deg <= 1.0;
  wrong += err_m > 1.0 || err_deg > 3.0;
}

double QueryLog::total_median() const {
  std::vector<double> v;
  for (const ModuleTimings& t : timings) v.push_back(t.total_ms);
  return median(v);
}

void QueryLog::print(const char* title) const {
  std::printf("\n%s: %zu queries, one at a time on the calling thread\n", title, timings.size());
  if (timings.empty()) return;
  std::printf("  %-10s %10s %10s\n", "module", "median ms", "p90 ms");
  for (const ModuleField& m : kModules) {
    std::vector<double> v;
    for (const ModuleTimings& t : timings) v.push_back(t.*m.ms);
    std::printf("  %-10s %10.1f %10.1f\n", m.name, median(v), quantile(v, 0.9));
  }
  std::printf("  %-10s %10.1f %10.1f   (process CPU time; > total means more than one core)\n", "total CPU",
              median(cpu), quantile(cpu, 0.9));
  std::printf(
      "  per query (median / p90): %.0f / %.0f points, %.0f / %.0f segments, %.0f / %.0f candidates, "
      "%.0f / %.0f matches (at most %.0f: the size of verification's consistency graph)\n",
      median(points), quantile(points, 0.9), median(segments), quantile(segments, 0.9), median(candidates),
      quantile(candidates, 0.9), median(matches), quantile(matches, 0.9),
      matches.empty() ? 0.0 : *std::max_element(matches.begin(), matches.end()));
  std::printf("  localized %zu / %zu (%zu within 0.2 m and 1 deg of the reference pose, %zu off by > 1 m or > 3 deg)\n",
              localized, timings.size(), accurate, wrong);
}

}  // namespace segmatch::bench
