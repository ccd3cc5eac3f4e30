// Pictures of generated data: a top-down map of the world with the trajectories, and one
// simulated scan (range image plus a bird's-eye view coloured by semantic class).
#pragma once

#include "segmatch/sim/lidar.h"
#include "segmatch/sim/traversal.h"
#include "segmatch/sim/world.h"

#include <string>

namespace segmatch::sim {

// Draws `world` (and, when given, what changed in `changed`: new cars and pedestrians) with
// the first traversal in blue and the second in orange. Throws std::runtime_error if the
// image cannot be written.
void write_world_png(const std::string& path, const World& world, const World* changed, const Traversal& first,
                     const Traversal* second);

void write_scan_png(const std::string& path, const SimulatedScan& scan, const LidarModel& model,
                    const std::string& title);

}  // namespace segmatch::sim
