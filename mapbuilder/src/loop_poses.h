// segmatch-mapbuilder --close-loops: the traversal's poses are an odometry that drifts; loops
// are detected and the pose graph optimised first (posegraph/close_loops.h), and the map is
// built on the corrected poses.
#pragma once

#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/sequence.h>
#include <segmatch/storage/map_types.h>

#include <nlohmann/json.hpp>

#include <csignal>
#include <optional>
#include <vector>

namespace segmatch::mapbuilder {

struct LoopCorrectedPoses {
  Poses T_map_sensor;      // one per frame given, corrected
  nlohmann::json summary;  // loops, down-weighted loops, correction size: stored in the map
};

// frames: the scans the map is built from (increasing). classifier: the model the map stores
// (used when the profile's matcher is the random forest; otherwise, or without one, L2).
// scan_edges: register consecutive scans too (posegraph/scan_edges.h; default settings).
// *stop_signal non-zero stops early (the caller then writes no map).
LoopCorrectedPoses close_loops_first(const io::Sequence& sequence, const std::vector<size_t>& frames,
                                     const io::PipelineConfig& config,
                                     const std::optional<storage::ClassifierBlob>& classifier, bool scan_edges,
                                     const volatile std::sig_atomic_t* stop_signal);

}  // namespace segmatch::mapbuilder
