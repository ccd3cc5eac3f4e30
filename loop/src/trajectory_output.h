// What segmatch-loop --optimize adds: the corrected trajectory, its error against the
// reference, the loops the optimiser down-weighted, and a picture of odometry vs corrected
// vs reference.
#pragma once

#include <segmatch/posegraph/close_loops.h>
#include <segmatch/posegraph/pose_graph.h>

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

namespace segmatch::loop {

struct TrajectorySummary {
  std::optional<posegraph::TrajectoryError> odometry, corrected;  // set with a reference
  std::vector<posegraph::LoopReport> loop_weights;                // of the final solve
  size_t solves = 0;
  double median_solve_ms = 0, max_solve_ms = 0;
  size_t map_segments_odometry = 0, map_segments_corrected = 0, merged_duplicates = 0;
  // Scan edges (--scan-edges): registrations tried, accepted, down-weighted at the end; with a
  // reference, the median error of each accepted step and of the odometry's same steps.
  size_t scan_edges_tried = 0, scan_edges_accepted = 0, scan_edges_downweighted = 0;
  struct StepError {
    double median_m = 0, median_deg = 0, median_scale_pct = 0;  // scale: (|step| / |reference step| - 1)
  };
  std::optional<StepError> scan_step_error, odometry_step_error;
};

// reference: T_world_sensor of each frame fed (empty: no reference).
TrajectorySummary summarize(const posegraph::ClosedLoops& r, const Poses& reference);
nlohmann::json to_json(const TrajectorySummary& s, const std::vector<LoopClosure>& loops);
void print_summary(const TrajectorySummary& s, const std::vector<LoopClosure>& loops);

// "t x y z qx qy qz qw" per pose (TUM RGB-D), times in seconds. Throws on write failure.
void write_tum(const std::string& path, const std::vector<double>& times, const Poses& poses);

// Top-down: odometry (grey), corrected (blue), reference (green, when given, aligned on the
// first pose like the error), loop edges on the corrected trajectory (orange; red when the
// optimiser down-weighted them); with a reference, a strip below plots the position error
// along the route. Throws std::runtime_error when it cannot write.
void write_trajectory_png(const std::string& path, const posegraph::ClosedLoops& r, const Poses& reference,
                          const TrajectorySummary& s);

}  // namespace segmatch::loop
