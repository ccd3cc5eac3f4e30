// segmatch-bench-server's world: the tiny city's map (segments, surface layer, classifier) and the
// revisit's queries as a vehicle would send them (local clouds from drifting odometry, and its
// newest scans). Built once per run, before any timing.
#pragma once

#include <segmatch/api/protocol.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/sim/city.h>

#include <string>
#include <vector>

namespace segmatch::bench {

// One request per local cloud of the revisit (every every_m), voxelized with `voxel` when given;
// T_map_local_prior holds the truth (sent only with a prior flag), newest_points the last 10 m of
// kept scans placed by the odometry (sent only with the newest-scans flag).
std::vector<api::LocalizeRequest> revisit_requests(const sim::City& city, const LocalCloudConfig& local_cloud,
                                                   const VoxelGridConfig* voxel, double every_m);

// The map of the first traversal, in a temporary file (its path): segments, surface layer and,
// when `model` is not empty, the classifier.
std::string build_map(const sim::City& city, const io::PipelineConfig& config, const std::string& model);

}  // namespace segmatch::bench
