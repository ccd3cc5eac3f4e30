// Cold start: which place of the map a single scan shows (beyond the paper). The paper's
// segments need a cloud of some tens of metres: one sparse scan yields a few partial views of
// objects, too few to verify four matches. A whole scan still says where it was taken: Scan
// Context (Kim & Kim, "Scan Context: Egocentric spatial descriptor for place recognition within
// 3D point cloud map", IROS 2018) bins the points around the sensor by ring (range) and sector
// (bearing) and keeps the highest point of each bin above the ground. The map's places are
// described the same way from its surface layer along its trajectory; the query's descriptor is
// compared with each place's under every rotation by a sector, which also gives the heading.
// The best places are only candidates: registration onto the surface layer around each, with
// every tracking gate, decides (Localizer::recognize_place).
#pragma once

#include "segmatch/core/common/types.h"

#include <Eigen/Core>

#include <atomic>
#include <functional>
#include <future>
#include <memory>
#include <vector>

namespace segmatch {

struct PlaceRecognitionConfig {
  bool enabled = true;
  int rings = 20;              // range bins out to max_radius_m
  int sectors = 60;            // bearing bins (6 degrees each): the heading's first guess
  float max_radius_m = 40.0f;  // the surface layer keeps 40 m of each scan (SurfaceLayerConfig)
  // A bin's value is the height of its highest point above the ground, clamped to
  // max_height_m; bins whose points lie below min_height_m are empty (ground alone is seen
  // differently by a single scan and by the map's accumulated layer).
  float min_height_m = 0.8f;
  float max_height_m = 3.0f;
  bool occlusion = true;
  float block_height_m = 2.0f;
  float place_spacing_m = 1.0f;  // places along the map's trajectory, at least this far apart
  float lateral_step_m = 2.0f;   // ... and beside it, this far apart
  int lateral_steps = 2;         // on each side
  // Places compared in full, the nearest by ring key; 0: every place. The ring key (the share of
  // occupied sectors per ring) counts points, and one sparse scan fills far fewer bins than the
  // map's accumulated layer: the true place's key can rank anywhere
  // (docs/how-defaults-were-chosen.md).
  int shortlist = 0;
  int candidates = 10;  // places handed to registration, best first
  // Each candidate is a prior for the surface layer's wide-prior tracking: a disc of this
  // radius (the query may be a lane or two and half a place spacing away) and this heading
  // tolerance. The best shift of one sparse scan's bins can be several sectors off the heading
  // its registration settles on (docs/how-defaults-were-chosen.md); the fitness gate, not the
  // heading, parts true from wrong places.
  float prior_radius_m = 8.0f;
  float heading_tolerance_deg = 30.0f;
  float max_distance = 0.65f;  // candidates farther than this (0 same, 1 unrelated) are not tried
  // The tracking gates for a cold start, in place of the tracker's. One scan holds a few
  // segments, too few to witness a pose (true and false poses alike had 0-11 landing, 0-3
  // matched): the registration's fitness decides. True poses fitted 0.957-0.999, the best false
  // ones 0.883 (simulated demo city, HDL-64E) and 0.723 (riverside02 keyframes); docs/how-defaults-were-chosen.md.
  int min_support = 0;               // query segments landing on map segments under the pose
  int min_matched_segments = 0;      // of those, passing the matcher
  float min_fitness = 0.92f;         // of the registration (and of the search's peaks)
  float max_shifted_support = 0.0f;  // SurfaceTrackingConfig's look-alike check (0: off)
  float fitness_margin = 0.05f;      // a distinct place fitting within this of the best: ambiguous
  // The elevations the map's sensor saw, from the sensor (the profile's 1st and 99th
  // percentiles, measured when the map was built; io sets them from the map's "measured").
  // A scan from another sensor class sees more: a VLP-16 walls to +15 degrees where an HDL-64E
  // map holds them to +2. Those points have no counterpart in the map and only lower the
  // fitness, so a cold start whose scan reaches more than elevation_excess_deg beyond this band
  // (a vehicle's roll and pitch, an odometry frame's tilt, stay within it) keeps the points
  // within the band widened by elevation_margin_deg. Unmeasured maps: -90..90, nothing dropped.
  float map_elevation_min_deg = -90.0f;
  float map_elevation_max_deg = 90.0f;
  float elevation_excess_deg = 5.0f;
  float elevation_margin_deg = 1.5f;
  void validate() const;  // throws std::invalid_argument naming the field
};

struct PlaceDescriptor {
  int rings = 0, sectors = 0;
  std::vector<float> cells;     // rings x sectors, ring-major; 0 = empty
  std::vector<float> ring_key;  // per ring, the share of occupied sectors (rotation invariant)
  double ground_z = 0.0;        // the ground's height under the centre, in the points' frame
  size_t occupied() const;
};

// The descriptor of the points (any frame) around `centre`, sector 0 starting at bearing
// heading_rad (counter-clockwise about +z). Only points within max_radius_m horizontally count.
PlaceDescriptor describe_place(const PointCloud& points, const Eigen::Vector3d& centre, double heading_rad,
                               const PlaceRecognitionConfig& config);

// Scan Context's distance (0 same, 1 unrelated) at its best rotation: shift_sectors is the k for
// which sector j of `query` corresponds to sector j + k of `place`.
struct PlaceDistance {
  double distance = 1.0;
  int shift_sectors = 0;
};
PlaceDistance place_distance(const PlaceDescriptor& query, const PlaceDescriptor& place);

// A descriptor's sectors as columns of ring values, each of unit length (sector-major), and which
// are occupied: what place_distance compares, computed once per place by PlaceIndex.
struct PlaceColumns {
  int rings = 0, sectors = 0;
  std::vector<float> values;
  std::vector<float> occupied;  // 1 or 0 per sector (floats: shared sectors are a dot product)
};
PlaceColumns place_columns(const PlaceDescriptor& d);
PlaceDistance place_distance(const PlaceColumns& query, const PlaceColumns& place);

struct PlaceCandidate {
  size_t place = 0;
  double distance = 1.0;
  // The query frame in the map: the query's sensor at the place, turned by the best shift,
  // its ground on the place's (gravity-aligned: no roll or pitch).
  Pose3d T_map_query = Pose3d::Identity();
};

class PlaceIndex {
 public:
  explicit PlaceIndex(const PlaceRecognitionConfig& config = {});
  // A place: the map sensor's pose and the descriptor of the map around it (heading: the pose's yaw).
  void add(const Pose3d& T_map_sensor, PlaceDescriptor descriptor);
  // The candidates for a query described around sensor_query (query frame) with heading 0,
  // best first, at most config.candidates, none above config.max_distance.
  std::vector<PlaceCandidate> query(const PlaceDescriptor& descriptor, const Eigen::Vector3d& sensor_query) const;
  size_t size() const { return poses_.size(); }
  const Pose3d& pose(size_t place) const { return poses_[place]; }
  const PlaceRecognitionConfig& config() const { return config_; }

 private:
  PlaceRecognitionConfig config_;
  std::vector<Pose3d> poses_;
  std::vector<PlaceDescriptor> descriptors_;  // cells dropped once in columns_
  std::vector<PlaceColumns> columns_;
};

// The places of a map: along `trajectory` (T_map_sensor), one at least place_spacing_m from the
// previous, each described from `points_near(centre, radius_m)` (the surface layer). Stops early,
// with the places so far, once `cancel` (if given) is set.
PlaceIndex build_place_index(const std::vector<Pose3d>& trajectory,
                             const std::function<PointCloud(const Eigen::Vector3d&, double)>& points_near,
                             const PlaceRecognitionConfig& config, const std::atomic<bool>* cancel = nullptr);

// A map's places as a server gets them: described in the background while it already answers
// (a city's take seconds), waited for by the first cold start that needs them. An invalid
// future, or a null index, is a map without places.
using PlacesFuture = std::shared_future<std::shared_ptr<const PlaceIndex>>;
PlacesFuture ready_places(std::shared_ptr<const PlaceIndex> places);

// The yaw (about +z) of a pose's x axis.
double yaw_of(const Pose3d& T);

}  // namespace segmatch
