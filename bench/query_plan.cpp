#include "query_plan.h"

#include "segmatch/core/detail/random.h"
#include "segmatch/sim/traversal.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace segmatch::bench {

std::vector<size_t> spread(size_t count, size_t n) {
  std::vector<size_t> out;
  if (count == 0 || n == 0) return out;
  if (count <= n) n = count;
  for (size_t k = 0; k < n; ++k) out.push_back(n == 1 ? count / 2 : (k * (count - 1) + (n - 1) / 2) / (n - 1));
  return out;
}

std::vector<size_t> scheduled_frames(const sim::Traversal& t, const LocalCloudConfig& lc,
                                     const sim::LocalCloudSchedule& s) {
  std::vector<size_t> out;
  if (t.size() == 0) return out;
  size_t last_kept = 0;
  bool any = false;
  double next = t.odometer_m[s.first_frame] + s.warmup_m;
  for (size_t i = s.first_frame; i <= std::min(s.last_frame, t.size() - 1); ++i) {
    if (any && (t.T_world_lidar[i].translation() - t.T_world_lidar[last_kept].translation()).norm() <
                   lc.min_travel_between_scans_m)
      continue;
    any = true;
    last_kept = i;
    if (t.odometer_m[i] < next) continue;
    next = t.odometer_m[i] + s.every_m;
    out.push_back(i);
  }
  return out;
}

QueryPlan plan_queries(const sim::City& city, int queries, int pcl_clouds, uint64_t seed, int threads) {
  const std::vector<sim::RevisitMatch> revisits = sim::match_revisits(city.first, city.second);
  std::vector<double> to_map(city.second.size(), INFINITY);
  for (const sim::RevisitMatch& m : revisits) to_map[m.frame] = m.distance_m;
  double revisit_m = 0;
  for (size_t f = 1; f < city.second.size(); ++f)
    if (to_map[f] <= 5.0 && city.second.odometer_m[f] >= kQueryWarmupM)
      revisit_m += city.second.odometer_m[f] - city.second.odometer_m[f - 1];
  QueryPlan plan;
  plan.schedule.every_m = std::clamp(revisit_m / (1.5 * queries), 1.0, 10.0);
  plan.schedule.warmup_m = kQueryWarmupM;
  plan.schedule.seed = mix_seed(seed, 31);
  plan.schedule.threads = threads;
  std::vector<size_t> eligible;
  for (size_t f : scheduled_frames(city.second, LocalCloudConfig{}, plan.schedule))
    if (to_map[f] <= 5.0) eligible.push_back(f);
  const std::vector<size_t> picks = spread(eligible.size(), static_cast<size_t>(queries));
  for (size_t i : picks) plan.selected.insert(eligible[i]);
  for (size_t i : spread(picks.size(), static_cast<size_t>(pcl_clouds))) plan.compared.insert(eligible[picks[i]]);
  std::printf(
      "queries: %zu local clouds of the second traversal within 5 m of the first (%.0f m of it), one "
      "every %.1f m after >= %.0f m of driving (%zu candidates), in the odometry frame of its first pose\n",
      plan.selected.size(), revisit_m, plan.schedule.every_m, kQueryWarmupM, eligible.size());
  if (plan.selected.size() < static_cast<size_t>(queries))
    std::printf("note: fewer queries than the %d requested: the second traversal is too short\n", queries);
  return plan;
}

}  // namespace segmatch::bench
