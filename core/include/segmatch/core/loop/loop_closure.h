// Online loop-closure detection (paper section IV-D, "Loop-closure performance"): "the target
// map is built online by accumulating segments extracted from the source clouds". While
// driving, scans are accumulated in the odometry frame into a local cloud (local_cloud.h);
// every local_cloud_every_m metres the local cloud is segmented and described, its segments
// are matched against the segments of earlier local clouds (paper III-D), the matches are
// verified geometrically (III-E) and refined (beyond the paper), and a verified match means
// the vehicle is back at a place it has seen: a loop, with the 6DOF correction of the
// odometry. The local cloud's segments then join the growing target map.
//
// Recent past. Objects around the vehicle are in the map from the previous local clouds and
// would trivially match themselves. Target segments last seen within
// exclude_recent_distance_m of driving (and within exclude_recent_time_s, for a vehicle that
// stands still) are therefore excluded from matching.
//
// Duplicate merging across a loop. The map keeps one segment per object (the most complete
// view, as SegmentMap). But odometry drifts: back at a place seen long ago, an object appears
// shifted in the odometry frame, and merging by position alone would fuse the old view with
// the new one (or, with drift above the merge distance, keep both anyway), corrupting the
// evidence the next local clouds of the revisit should match. Choice made here: a new
// segment merges only with a map segment last seen within the recent-past window, i.e. one
// that is itself excluded from matching. Old segments are frozen: never replaced, never
// refreshed, so they stay eligible for matching and keep the frame they were seen from. The
// revisit builds a second, recent copy of the place which merges with itself as usual.
// A consequence is that the set of eligible targets only grows, so the target index can be
// rebuilt lazily (rebuild_every_local_clouds) without ever matching a recent segment.
//
// Scans are accumulated in two VoxelAccumulators (the local cloud, voxelized incrementally),
// so a step crops voxels rather than millions of raw points.
//
// Knows no files: the caller feeds scans and odometry poses.
#pragma once

#include <algorithm>

#include "segmatch/core/localization/local_cloud.h"
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/mapping/segment_map.h"

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace segmatch {

struct LoopDetectorConfig {
  // Scans accumulated in the odometry frame (paper IV-A: a scan every 1 m, 60 m cylinder).
  LocalCloudConfig local_cloud;
  // Segmentation, description, retrieval, matcher (kRandomForest needs a classifier),
  // verification, support ranking and refinement, exactly as for localization.
  LocalizerConfig localizer;
  // Views closer than duplicate_distance_m are merged, but only among recent segments (above).
  SegmentMapConfig segment_map;
  // The query local cloud holds only scans of the last local_cloud_history_m of driving
  // (between half of it and all of it: two local clouds restart alternately). Without this
  // bound a scan whose bounding box still touches the cylinder is never dropped, and back at
  // a place the query would contain the old scans themselves in the old odometry coordinates
  // and "match" the old view with the drift left in. Must not exceed exclude_recent_distance_m,
  // so that no view is both in the query and among the targets.
  double local_cloud_history_m = 120.0;
  // Segment and match the local cloud each time the odometer advanced this much. The first
  // local cloud is processed once the odometer reaches this distance too.
  double local_cloud_every_m = 10.0;
  // Target segments last seen less than this distance driven ago are not matched (and are the
  // only ones new views merge with). Must exceed the stretch over which one object stays in
  // the local cloud (about twice local_cloud.radius_m when driving past it), else the vehicle
  // "closes a loop" with what it just saw.
  double exclude_recent_distance_m = 150.0;
  // Also excluded: target segments last seen less than this many seconds ago (0 = distance
  // only). Covers a vehicle standing still, whose odometer does not advance.
  double exclude_recent_time_s = 0.0;
  // A loop is reported only with at least this many verified inlier matches (on top of the
  // localizer's verification.min_inliers and min_support).
  int min_inliers = 5;
  // ... and a localizer confidence (0..1, grows with the support beyond min_support, scaled by
  // the refinement's fitness) of at least this. On the simulated loop test a false loop had 5
  // inliers, support 12, confidence 0.45; true loops had 0.8 and above.
  float min_confidence = 0.6f;
  // Beyond the paper: if > 0, a loop is only accepted within this distance of where the
  // odometry itself puts the vehicle (the correction T_oldodom_odom moves the sensor by at most
  // this much). Odometry drift over one loop is bounded in practice (LiDAR-inertial odometry:
  // well under 1 % of the distance; LIO-SAM searches loop candidates within 15 m), and a bound
  // lets the true place win over distant look-alikes that the support alone calls ambiguous
  // (small scenes of few segments). 0: anywhere in the map. max_drift_deg bounds the heading
  // drift the same way (used only with max_drift_m > 0; see PosePrior).
  double max_drift_m = 0.0;
  double max_drift_deg = 5.0;
  // The same bound stated for odometry in general rather than for one recording: if > 0, the
  // bound is max(max_drift_m, max_drift_fraction * distance driven so far). Without pose-graph
  // corrections fed back, the drift against any past view is at most the drift accumulated
  // since the start, which grows with the distance driven (LIO: ~1 % of it).
  double max_drift_fraction = 0.0;
  // The bound in force after driving odometer_m (0: no bound).
  double drift_bound_m(double odometer_m) const {
    return max_drift_fraction > 0.0 ? std::max(max_drift_m, max_drift_fraction * odometer_m) : max_drift_m;
  }
  // The target index (k-d tree, centroid grid) is rebuilt at most once per this many local
  // clouds, and only when segments aged out of the recent-past window since the last build.
  // Segments that aged out since then are not matched until the next build.
  int rebuild_every_local_clouds = 1;
  void validate() const;  // throws std::invalid_argument naming the field
};

// A detected loop: the vehicle at query_frame is where it was at match_frame.
struct LoopClosure {
  size_t query_frame = 0;
  size_t match_frame = 0;  // local cloud most matched target segments' points come from (their kept view)
  double query_time_s = 0, match_time_s = 0;
  double query_odometer_m = 0, match_odometer_m = 0;
  // Relative pose (a pose-graph edge): maps points of the sensor at match_frame into the
  // sensor frame at query_frame, i.e. T_query_match = T_world_query^-1 * T_world_match with
  // the drift between the two removed.
  Pose3d T_query_match = Pose3d::Identity();
  // The correction of the odometry: maps the query's odometry coordinates into the odometry
  // coordinates of the old view (identity without drift).
  Pose3d T_oldodom_odom = Pose3d::Identity();
  size_t inliers = 0;
  size_t support = 0;       // query segments that land on a target segment under the pose
  float confidence = 0.0f;  // 0..1, from the localizer
};

// What one call of process() did.
struct LoopStep {
  bool processed = false;           // a local cloud was segmented and matched in this call
  std::optional<LoopClosure> loop;  // set when a loop was detected
  std::string reason;               // why no loop (empty when a loop was found or not processed)
  size_t query_segments = 0;        // segments of this local cloud
  size_t eligible_targets = 0;      // target segments matched against (older than the window)
  size_t map_segments = 0;          // all map segments after insertion
  bool rebuilt_index = false;
  ModuleTimings timings;  // of the localization (voxel = the incremental voxel grid's crop .. refine)
  double total_ms = 0;    // whole call, including local cloud crop, index rebuild, insertion
};

class LoopDetector {
 public:
  // classifier: required for MatcherType::kRandomForest, ignored for kL2.
  explicit LoopDetector(const LoopDetectorConfig& config,
                        std::shared_ptr<const RandomForestMatcher> classifier = nullptr);
  ~LoopDetector();
  LoopDetector(LoopDetector&&) noexcept;
  LoopDetector& operator=(LoopDetector&&) noexcept;

  // One scan (points in the sensor frame) at odometry pose T_odom_sensor. frame_index and
  // time_s identify the scan in the caller's sequence (frame indices must increase).
  // Accumulates; every local_cloud_every_m metres also segments, matches and inserts.
  // Throws std::invalid_argument for a non-increasing frame index or a non-finite pose.
  LoopStep process(const PointCloud& scan_points_sensor, const Pose3d& T_odom_sensor, size_t frame_index,
                   double time_s);

  const LoopDetectorConfig& config() const;
  double odometer_m() const;                      // distance driven so far (sum of odometry steps)
  size_t map_size() const;                        // target segments in the growing map
  const std::vector<LoopClosure>& loops() const;  // every loop detected so far
  Segments map_segments() const;                  // copy of the map (odometry frame), for pictures and tests
  // For each map segment (same order), the local cloud its points come from (its kept view):
  // the keyframe it moves with when the trajectory is corrected (map_correction.h).
  std::vector<size_t> map_segment_frames() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace segmatch
