// The local cloud (paper III-A, IV-A): scans accumulated in a consistent (world) frame, a
// scan being added every time the robot drove 1 m, from which "a cylindrical neighbourhood
// of radius R [= 60 m], centred around the current robot location" is extracted.
#pragma once

#include <cstdint>
#include <deque>
#include <vector>

#include "segmatch/core/common/types.h"

namespace segmatch {

struct LocalCloudConfig {
  double radius_m = 60.0;                   // cylinder radius (horizontal distance), IV-A
  double min_travel_between_scans_m = 1.0;  // straight-line distance to the last added scan
  // Optional uniform subsampling of each added scan: keep the first point of every cube of
  // this edge (0 = off). The paper drops half of each scan (IV-A) to bound the cloud size.
  double subsample_leaf_m = 0.0;
  // A scan leaves the cloud once the vehicle drove more than this since it was added (0: only
  // when its bounding box leaves the cylinder). A raw scan reaches 100 m and more, so without
  // it a scan stays until the vehicle is radius + range away, and on a block it drives around
  // far longer: odometry that built the cloud drifts over all that driving, and where the route
  // returns the same street is held twice, metres apart. 60 m (one radius): chosen on the demo
  // city with simulated LiDAR-inertial odometry, riverside02 0-164, hku-mb and hku-loop1
  // (docs/how-defaults-were-chosen.md, "What we measured"); maps written before it keep 0.
  double max_scan_age_m = 60.0;
  void validate() const;  // throws std::invalid_argument naming the field
};

// The same cloud without the age limit: a map's local clouds, whose poses are the mapping
// run's reference, hold every scan until it leaves the cylinder (MapBuilder, sim's map segments).
inline LocalCloudConfig without_age_limit(LocalCloudConfig c) {
  c.max_scan_age_m = 0.0;
  return c;
}

class LocalCloud {
 public:
  explicit LocalCloud(const LocalCloudConfig& config = {});

  // Adds a scan (points in the sensor frame) taken at T_world_sensor if the sensor moved at
  // least min_travel_between_scans_m (straight line) since the last added scan; the first
  // scan is always added. Returns whether it was added. Optional per-point labels (same
  // size as the scan) are carried along. Non-finite points are dropped.
  bool add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor,
                const std::vector<uint32_t>* labels = nullptr);

  // Points (world frame) within radius_m horizontally of the position of T_world_sensor,
  // scans in insertion order. Drops stored scans wholly outside the cylinder to bound
  // memory. labels_out gets the carried labels (0 for scans added without labels).
  PointCloud crop(const Pose3d& T_world_sensor, std::vector<uint32_t>* labels_out = nullptr);

  size_t scan_count() const { return scans_.size(); }
  size_t point_count() const;
  void clear();

 private:
  struct Scan {
    PointCloud points;             // world frame
    std::vector<uint32_t> labels;  // empty if none were given
    float min_xy[2] = {0.f, 0.f};  // horizontal bounding box, for dropping whole scans
    float max_xy[2] = {0.f, 0.f};
    double added_at_m = 0.0;  // odometer when it was added
  };
  LocalCloudConfig config_;
  std::deque<Scan> scans_;
  double odometer_m_ = 0.0;  // distance between the added scans' positions, summed
  bool has_last_ = false;
  Eigen::Vector3d last_position_ = Eigen::Vector3d::Zero();
};

}  // namespace segmatch
