// Drives through a generated world: routes through the street graph, a smooth path in a
// lane with rounded corners, a speed profile, and one sensor pose every scan period.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/sim/world.h"

#include <vector>

namespace segmatch::sim {

struct DriveConfig {
  double cruise_speed_mps = 10.0;       // urban speed (36 km/h)
  double max_lateral_accel_mps2 = 2.0;  // slows the vehicle down in turns
  double max_accel_mps2 = 1.5;          // acceleration and braking limit
  double right_turn_radius_m = 7.0;
  double left_turn_radius_m = 11.0;
  double scan_period_s = 0.1;     // one scan every 0.1 s (10 Hz)
  double sensor_height_m = 1.73;  // LiDAR above the road (KITTI)
  // Lane choice. Traffic drives on the right. On streets with two lanes per direction,
  // inner_lane picks the left one; lane_shift_m moves the vehicle towards the centre line
  // within its lane (negative: towards the kerb).
  bool inner_lane = false;
  double lane_shift_m = 0.0;
};

// A route: a sequence of adjacent street-graph nodes, never turning back.
struct Route {
  std::vector<int> nodes;
};

struct Traversal {
  std::vector<double> times_s;     // scan time stamps
  Poses T_world_lidar;             // sensor pose of every scan
  std::vector<double> odometer_m;  // distance driven at every scan
  std::vector<int> edge;           // street-graph edge driven at every scan
  std::vector<bool> forward;       // whether that edge is driven from its node a to b

  size_t size() const { return times_s.size(); }
  double length_m() const { return odometer_m.empty() ? 0.0 : odometer_m.back(); }
};

// Random route of at least length_m, preferring streets it has not driven yet.
Route plan_route(const StreetGraph& graph, double length_m, Rng& rng);

// A closed route around the city: its outer nodes in clockwise order back to the start, then
// its first `again` nodes once more (a loop that drives its first streets twice, for loop
// closure). Throws std::runtime_error when the outer nodes do not form a route.
Route plan_loop_route(const StreetGraph& graph, int again);

// A route for a revisit: starts on a street of `first`, drives streets of `first` in the
// same and in the opposite direction, and some streets `first` never drove.
Route plan_revisit_route(const StreetGraph& graph, const Route& first, double length_m, Rng& rng);

Traversal drive(const World& world, const Route& route, const DriveConfig& config);

// For each scan of `revisit`, the nearest scan of `reference` (by sensor position).
struct RevisitMatch {
  int frame = 0;                  // scan index in the revisit
  int reference_frame = -1;       // nearest scan of the reference traversal
  double distance_m = 0.0;        // horizontal distance between the two sensor positions
  double heading_diff_deg = 0.0;  // 0: same direction, 180: opposite
};
std::vector<RevisitMatch> match_revisits(const Traversal& reference, const Traversal& revisit);

}  // namespace segmatch::sim
