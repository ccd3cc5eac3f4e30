// Localization evaluation: a second traversal is replayed as a vehicle would
// (io::replay_sequence), each query goes to a localizer (the server over the protocol, or the
// same code in-process), and every answer is scored against the ground truth.
#pragma once

#include <segmatch/api/protocol.h>
#include <segmatch/eval/metrics.h>
#include <segmatch/io/replay.h>
#include <segmatch/io/sequence.h>

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace segmatch {
namespace eval {

using LocalizeFn = std::function<api::LocalizeReply(const api::LocalizeRequest&)>;

struct LocalizationRunConfig {
  std::string map_path;      // the map (its trajectory decides which streets are mapped)
  std::string query_folder;  // sequence to replay: a folder or a ROS 2 bag
  io::BagOptions bag;        // which topics of a bag (io/sequence.h); its poses are the truth
  // Ground truth T_map_sensor of every query scan: by default the query sequence's own poses
  // are in the map frame (same recording, e.g. riverside02 even / odd keyframes). With
  // sim_dataset, a segmatch-sim folder: queries = sequences/01, truth from ground_truth/
  // lidar_poses_01.txt expressed in the frame of the first scan of sequence 00 (the map's).
  std::string sim_dataset;
  io::ReplayConfig replay;
  Thresholds thresholds;
  bool print_each = true;  // one line per query on stdout
  // With a narrow prior and newest scans, ask the server to track on the surface layer first
  // (LOCALIZE bit 6, protocol revision 11); --track-surfaces off clears it.
  bool track_surfaces = true;
  // The local clouds are accumulated with the vehicle's odometry, as on a car: odometry_path,
  // or the replayed sequence's odom_poses.txt when empty (io::odometry_poses_path; a bag: its
  // own poses, which a bag records from the vehicle's odometry, or a TUM file matched by time). The
  // sequence's poses only score. kReference builds them from the reference poses instead (a
  // comparison: it flatters every figure), and the report says so.
  io::CloudPoses cloud_poses = io::CloudPoses::kOdometry;
  std::string odometry_path;
  // Score against this poses file of the query sequence instead of its poses.txt (e.g.
  // hku-loop1's odom_poses.txt, the trustworthy one at its revisit). Empty: poses.txt.
  std::string reference_path;
  // The vehicle's local cloud holds scans for this many metres of driving instead of the
  // map's local_cloud.max_scan_age_m (a what-if; negative: the map's).
  double max_scan_age_m = -1.0;
  // Tracking between fixes (api::Tracker): each query's prior comes from the last fix.
  bool track = false;
  // GNSS-like priors: each query's prior is the true pose with Gaussian noise of this many
  // metres per horizontal axis (seeded), radius 3 sigma. 0: none. Excludes track.
  double gnss_sigma_m = 0.0;
  uint64_t gnss_seed = 1;
  // A stress test (a wrong prior must never become a fix): every query's prior is the
  // true pose moved wrong_prior_m in a random horizontal direction (seeded by gnss_seed), with
  // radius wrong_prior_radius_m. 0: off. Excludes track and gnss_sigma_m.
  double wrong_prior_m = 0.0, wrong_prior_radius_m = 3.0;
  // Same-run A/B: every query sent with a prior is also sent without one (not scored), and the
  // server times of both are reported.
  bool compare_global = false;
};

struct LocalizationRun {
  std::vector<QueryOutcome> outcomes;
  Summary summary;
  std::map<std::string, Distribution> module_ms;  // per-module time over all queries
  std::vector<Eigen::Vector3d> map_trajectory;
  std::string title;
  io::ReplayConfig replay;  // as run, so that a regression test can replay the same queries
  io::CloudPoses cloud_poses = io::CloudPoses::kOdometry;
  std::string cloud_poses_file;  // the poses file the local clouds were built with
  std::string reference_file;    // the poses file the answers are scored against (--query)
  // From the first localization on (tracking's figure: a pose carried by odometry alone is not
  // a localization): queries on mapped streets, and those the server answered LOCALIZED; the
  // queries on unmapped streets apart (a map cannot answer for a street it never saw).
  size_t after_first_fix = 0, localized_after_first_fix = 0;
  size_t unmapped_after_first_fix = 0, unmapped_localized_after_first_fix = 0;
  std::map<std::string, Distribution> server_ms_by_mode;  // server_total per query mode
  // With compare_global, over the queries sent with a prior: server_total and retrieve +
  // classify + verify, with the prior and for the same query without it.
  Distribution ab_prior_server_ms, ab_prior_match_ms, ab_global_server_ms, ab_global_match_ms;
};

// Throws io::IoError / storage::StorageError / std::runtime_error naming the bad input.
LocalizationRun run_localization(const LocalizationRunConfig& config, const LocalizeFn& localize);

// The replayed sequence and the true map pose of each of its scans: --query's poses (or
// --reference), or a segmatch-sim folder's sequences/01 with its exact ground truth, put in the
// frame of the map built from 00 (its first pose).
struct Truth {
  io::Sequence sequence;
  Poses T_map_sensor;
};
Truth open_truth(const LocalizationRunConfig& config);

// out_dir/localization.json, estimated.tum and reference.tum (localized queries, for evo),
// trajectory.png, px.png, errors.png; prints the summary.
void write_localization_report(const LocalizationRun& run, const std::string& out_dir);
void print_summary(const LocalizationRun& run);

}  // namespace eval
}  // namespace segmatch
