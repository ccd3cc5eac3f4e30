// A correlative search over a wide prior (beyond the paper). Registration needs a start within
// a metre or two of the truth; a GNSS fix (sigma ~10 m) or a tracker's prediction after a long
// stretch without a fix is ten times wider. Cartographer-style correlative scan matching (Olson,
// "Real-time correlative scan matching", ICRA 2009) covers that disc exhaustively: the map's
// points near the prior are rasterised top-down into a smoothed likelihood grid, and every
// heading within the prior's tolerance and every cell within its radius is scored by the sum of
// the grid under the query's points. The best distinct peaks are starting points for
// registration (registration.h), whose gates decide; several passing is an ambiguity.
#pragma once

#include "segmatch/core/common/types.h"

#include <Eigen/Core>

#include <vector>

namespace segmatch {

struct CorrelativeSearchConfig {
  bool enabled = true;
  // Priors up to this wide (and wider than RegistrationConfig::max_prior_radius_m) are searched;
  // wider ones go to segment matching alone.
  float max_radius_m = 40.0f;
  float resolution_m = 1.0f;      // grid cell and translation step (ICP's coarse stage reaches 1.5 m)
  float angle_step_deg = 1.0f;    // heading step within the prior's tolerance
  int max_query_points = 1000;    // one query point per occupied cell, then every k-th
  int candidates = 3;             // distinct peaks handed to registration, best first
  float min_separation_m = 3.0f;  // peaks closer than this are one
  // A registration from a peak answers with this fitness at least (RegistrationConfig's is for
  // a prior within ICP's reach): along a street of facades the disc holds wrong minima that fit
  // about as well as a narrow prior's floor lets through. Its support must also reach the
  // localizer's own floors (LocalizerConfig::min_support and min_support_with_prior, the higher):
  // over a wide prior the search is nearly a global one.
  float min_fitness = 0.65f;
  void validate() const;  // throws std::invalid_argument naming the field
};

struct SearchCandidate {
  Pose3d T_map_query = Pose3d::Identity();
  double score = 0.0;  // mean grid value under the query's points, 0..1
};

// query_points: query frame; map_points: map frame; the sensor is at sensor_query in the query
// frame. Only query points within window_m of the sensor (horizontally) are scored: farther ones
// drift with the odometry (RegistrationConfig::window_m). Candidates move the prior's sensor
// position by at most radius_m horizontally and turn it about the vertical through the sensor by
// at most heading_tolerance_deg; height, roll and pitch are the prior's. At most
// config.candidates, best first; none without points.
std::vector<SearchCandidate> correlative_search(const PointCloud& query_points, const PointCloud& map_points,
                                                const Pose3d& T_map_query_prior, const Eigen::Vector3d& sensor_query,
                                                double radius_m, double heading_tolerance_deg, double window_m,
                                                const CorrelativeSearchConfig& config);

}  // namespace segmatch
