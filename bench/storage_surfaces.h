// segmatch-bench-storage's surface layer: a plausible one made along the map's route (ground
// and facades at a 0.25 m leaf, as a mapping run would see them), and its size per km, the time
// to open the map and to read the layer near a place.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/storage/map_types.h>

#include <string>
#include <vector>

namespace segmatch {
namespace bench {

// Ground within 30 m of the route (a gentle terrain, 1 cm of noise) and facades 15 m either
// side of it, 12 m tall, with a cross street every 80 m; one point per leaf_m voxel, at the
// voxel's centroid of a few returns (up to 5 cm from its centre).
PointCloud synthetic_surfaces(const std::vector<storage::Keyframe>& trajectory, float leaf_m);

// Opens the map and reads the layer near random places of the route `runs` times each: prints
// the layer's size (MB per km of the route), the median open time and the median near() time
// with the tiles read from the file (a fresh cache) and from the cache.
void report_surfaces(const std::string& path, double route_km, int runs, double radius_m);

}  // namespace bench
}  // namespace segmatch
