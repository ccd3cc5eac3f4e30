// What an input looks like, measured from its scans and poses (the `auto` profile).
// A sensor class is told by its geometry, not by a name the user has to know: how much of the
// horizon a scan covers (a spinning LiDAR 360 deg, a Livox Avia ~70 deg), how far it sees, how
// far apart its points are, and whether a SLAM front end already voxel-downsampled it (then
// the nearest neighbour of almost every point sits about one leaf away, even close to the
// sensor, where a raw scan's points are centimetres apart).
#pragma once

#include "segmatch/core/common/types.h"

#include <cstddef>
#include <string>
#include <vector>

namespace segmatch {

struct InputMeasurements {
  size_t scans_measured = 0;
  double points_per_scan = 0;    // median
  double azimuth_coverage = 0;   // fraction of 1-degree azimuth bins holding points (median)
  double elevation_min_deg = 0;  // 1st / 99th percentile of point elevations (median over scans)
  double elevation_max_deg = 0;
  double range_p50_m = 0;  // median and 95th percentile of point ranges (median over scans)
  double range_p95_m = 0;
  double spacing_p10_m = 0;      // nearest-neighbour distance within a scan: 10th percentile
  double spacing_p50_m = 0;      // and median (over sampled points of every measured scan)
  double spacing_per_range = 0;  // median of nearest-neighbour distance / range (angular step)
  double scan_distance_m = 0;    // median distance between consecutive scans' positions
  // Do the poses agree with the scans? Consecutive scans less than kAgreementMaxDistanceM apart
  // are put in the world by their poses; a pair disagrees when under half of the later scan's
  // points lie within kAgreementRadiusM of the earlier one (riverside02: 0.88-0.92 where the
  // SLAM poses hold, 0.23-0.49 from keyframe ~165 on, where ICP moves them by 1-6 m).
  size_t pairs_checked = 0;
  size_t pairs_disagreeing = 0;
  std::vector<size_t> disagreeing_pairs;  // index of the earlier scan of each (input order)
  // The beam layout of a raw spinning scan: its points' elevations (from the sensor, points at
  // least kRingMinRangeM away) fall into rings, one per laser, split where the sorted elevations
  // jump by more than kRingGapDeg; rings are the groups holding kRingMinShare of the points
  // within kRingMaxWidthDeg (a continuous spread of elevations is one wide group, no ring).
  // Resolved (ring_count > 0) when the rings hold kRingsResolvedShare of the points (median over
  // scans); keyframes a SLAM front end voxelized and non-repetitive scans (Livox) have no rings.
  double ring_count = 0;        // 0: not resolved
  double ring_spacing_deg = 0;  // median elevation step between neighbouring rings
  bool downsampled = false;     // spacing_p10_m >= kDownsampledSpacingM
  bool wide_fov = false;        // azimuth_coverage >= kWideFovCoverage
  // A raw scan has its 10th-percentile neighbour a few centimetres away (hku-loop1 / hku-mb:
  // 0.023 / 0.029 m); keyframes voxelized at 0.2 m have it near half the leaf (riverside02:
  // 0.096 m), centroids of neighbouring voxels being closer than the leaf.
  static constexpr double kDownsampledSpacingM = 0.06;
  static constexpr double kWideFovCoverage = 0.6;
  static constexpr double kAgreementRadiusM = 0.75;
  static constexpr double kAgreementMaxDistanceM = 10.0;
  static constexpr double kMinAgreement = 0.5;
  static constexpr double kRingMinRangeM = 5.0;
  static constexpr double kRingGapDeg = 0.1;
  static constexpr double kRingMaxWidthDeg = 0.5;
  static constexpr double kRingMinShare = 0.002;
  static constexpr double kRingsResolvedShare = 0.8;
  static constexpr double kWideElevationDeg = 70.0;  // an OS0 spans 90 degrees, an HDL-64E 27
  // "dense-spinning", "sparse-spinning" (keyframes of a 360-degree sensor), "narrow-fov": the
  // class the parameters follow (auto_profile.h).
  std::string sensor_class() const;
  // The beam layout for a person: "16-beam spinning", "32-beam spinning", "64/128-beam
  // spinning", "wide-fov spinning" (elevation span >= kWideElevationDeg), "spinning, rings not
  // resolved", "slam keyframes" (downsampled) or "narrow-fov".
  std::string beam_layout() const;
};

struct InputProfileConfig {
  size_t max_scans = 24;        // scans measured, spread evenly over the input
  size_t sample_points = 3000;  // points per scan whose nearest neighbour is measured
  void validate() const;
};

// Measures a sample of scans (sensor frame; scans_to_measure() picks them) and the poses of
// every scan of the input in order (T_world_sensor; may be empty: then scan_distance_m stays 0).
// Throws std::invalid_argument when no scan holds 10 finite points.
InputMeasurements measure_input(const std::vector<PointCloud>& scans, const Poses& T_world_sensor,
                                const InputProfileConfig& config = {});

// Fraction of (up to `sample` strided) points of scan b within radius_m of a point of scan a,
// both put in the world by their poses.
double pose_agreement(const PointCloud& a, const Pose3d& T_world_a, const PointCloud& b, const Pose3d& T_world_b,
                      double radius_m, size_t sample = 2000);

// Checks consecutive pairs (see InputMeasurements::pairs_checked) and records the result in m.
// pairs[k] = {scan k, scan k + 1} with their poses; only pairs closer than
// kAgreementMaxDistanceM are counted. first_index[k] names pair k in the input's numbering.
struct ScanPair {
  const PointCloud* a = nullptr;
  const PointCloud* b = nullptr;
  Pose3d T_world_a = Pose3d::Identity(), T_world_b = Pose3d::Identity();
  size_t index_a = 0;
};
void check_pose_agreement(const std::vector<ScanPair>& pairs, InputMeasurements& m);

// The rings of one scan's point elevations (degrees, any order; see InputMeasurements): how
// many, the median step between neighbours, and the share of the points they hold.
struct Rings {
  size_t count = 0;
  double spacing_deg = 0;
  double share = 0;
  double lowest_deg = 0, highest_deg = 0;        // the outermost rings' elevations
  double bottom_step_deg = 0, top_step_deg = 0;  // and the step next to each
  std::vector<double> centres_deg;               // every ring's elevation, increasing
  // The rings from lo_deg to hi_deg: those found plus, beyond the outermost, as many as their
  // step fits (steep rings meet the ground nearer than kRingMinRangeM and are not measured).
  double count_between(double lo_deg, double hi_deg) const;
};
Rings measure_rings(std::vector<double> elevations_deg);

// The 1st and 99th percentiles of the elevations (degrees) at which `sensor` sees the points of
// a cloud, from up to `sample` strided points farther than 0.1 m: the vertical field of view a
// query shows, as measure_input() records an input's (elevation_min_deg, elevation_max_deg).
// Both 0 for a cloud without such points.
struct ElevationBand {
  double min_deg = 0.0, max_deg = 0.0;
};
ElevationBand measure_elevations(const PointCloud& cloud, const Eigen::Vector3f& sensor, size_t sample = 4000);

// Which scans measure_input() looks at when given `count` of them (indices, increasing).
std::vector<size_t> scans_to_measure(size_t count, const InputProfileConfig& config = {});

}  // namespace segmatch
