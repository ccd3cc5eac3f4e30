// Localization figures in the paper's terms (section IV-C): true and false localizations,
// pose errors, and P(x), "the probability of travelling a given distance without successful
// localization in the target map" (equation 1):
//
//   P(x) = (sum of distance travelled without localization for >= x metres) / (total distance)
//
// Distance counts only where the vehicle drives streets the map covers (`mapped`): driving a
// street the map never saw cannot be localized and says nothing about the method.
#pragma once

#include <segmatch/core/common/types.h>

#include <cstddef>
#include <map>
#include <string>
#include <vector>

namespace segmatch {
namespace eval {

struct Thresholds {
  double false_translation_m = 1.0;  // a localization farther off than this is false
  double false_rotation_deg = 3.0;
  double mapped_radius_m = 10.0;  // a query is on a mapped street within this of the map's trajectory
};

struct QueryOutcome {
  size_t frame = 0;
  double odometer_m = 0.0;
  bool mapped = true;
  bool localized = false;                 // the localizer said so
  bool correct = false;                   // localized and within the thresholds
  double error_m = 0.0, error_deg = 0.0;  // when localized
  double latency_ms = 0.0;
  uint32_t inliers = 0, support = 0;  // the localizer's evidence (LocalizeReply)
  float confidence = 0.f;
  std::string status;           // the localizer's status word, for reports
  std::string mode = "global";  // how the query was asked: global, tracked (Tracker), gnss, wrong
  bool rejected = false;        // --track: the tracker's gate rejected this LOCALIZED answer
  double server_ms = 0.0;       // the server's own time (server_total)
  // The reply's detail (docs/protocol.md 6.4): how far the whole local cloud's pose and its
  // recent window's differ at the sensor (the odometry's warp over the cloud). 0 without.
  double window_warp_m = 0.0, window_warp_deg = 0.0;
  uint32_t window_points = 0;
  // What answered (the reply's detail, revision 7): "segments", "registration"; empty: not said.
  std::string method;
  // The reported covariance (revision 7), horizontally: its largest standard deviation in the
  // map's x-y plane, and the horizontal error's Mahalanobis distance under it (set by
  // score_covariance; has_covariance false: none reported).
  bool has_covariance = false;
  double sigma_h_m = 0.0, mahalanobis_h = 0.0;
  Eigen::Vector3d truth_xy = Eigen::Vector3d::Zero();     // map-frame truth position
  Eigen::Vector3d estimate_xy = Eigen::Vector3d::Zero();  // map-frame estimate when localized
  Pose3d T_map_sensor = Pose3d::Identity();               // the estimate when localized
  Pose3d T_map_sensor_truth = Pose3d::Identity();         // the reference pose of the query scan
  double time_s = 0.0;                                    // the query scan's time (times.txt)
};

// Fills correct / error_m / error_deg of a localized outcome from the estimated and true
// sensor poses (both map frame).
void score(QueryOutcome& outcome, const Pose3d& T_map_sensor_estimate, const Pose3d& T_map_sensor_truth,
           const Thresholds& thresholds);

// Fills has_covariance / sigma_h_m / mahalanobis_h of a scored, localized outcome from the
// reply's 6x6 covariance (rotation, then position; docs/protocol.md 6.4). A zero matrix: none.
void score_covariance(QueryOutcome& outcome, const Eigen::Matrix<double, 6, 6>& covariance);

struct Distribution {
  size_t count = 0;
  double median = 0, p90 = 0, max = 0, mean = 0;
};
Distribution distribution_of(std::vector<double> values);

struct PxCurve {
  std::vector<double> gaps_m;   // distance (on mapped streets) between consecutive true localizations
  double total_m = 0.0;         // mapped distance driven
  double x95_m = 0.0;           // smallest x with P(x) <= 0.05
  double p_of(double x) const;  // equation 1
};
PxCurve px_curve(const std::vector<QueryOutcome>& outcomes);

struct Summary {
  size_t queries = 0, mapped_queries = 0, localized = 0, correct = 0, false_localizations = 0;
  Distribution error_m, error_deg, latency_ms;  // errors of the correct localizations
  PxCurve px;
  std::map<std::string, size_t> localized_by_method;  // what answered, over localized queries
  // Calibration over the localized queries with a covariance: how many have their horizontal
  // error within the reported 3 sigma (Mahalanobis distance <= 3), and the reported 1-sigma.
  size_t with_covariance = 0, within_3_sigma = 0;
  size_t rejected = 0, rejected_false = 0;  // answers the tracker's gate rejected, and the false ones among them
  Distribution sigma_h_m;
};
Summary summarize(const std::vector<QueryOutcome>& outcomes);

}  // namespace eval
}  // namespace segmatch
