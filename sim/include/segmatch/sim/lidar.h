// Spinning LiDAR sensor models and scan simulation.
#pragma once

#include "segmatch/core/types.h"
#include "segmatch/sim/raycaster.h"

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch::sim {

struct LidarModel {
  std::string name;
  std::vector<float> elevations_deg;  // one per beam
  int columns = 0;                    // azimuth steps per revolution
  float min_range_m = 0.9f;
  float max_range_m = 120.0f;
  float range_noise_sigma_m = 0.02f;  // Gaussian range noise
  float dropout_probability = 0.02f;  // returns lost at random
  float rate_hz = 10.0f;              // revolutions per second
  float mount_height_m = 1.73f;       // sensor height above the ground it stands on

  size_t rays_per_scan() const { return elevations_deg.size() * static_cast<size_t>(columns); }
};

// Velodyne HDL-64E (KITTI): 64 beams, -24.9..+2.0 deg, 0.17 deg azimuth at 10 Hz, 120 m.
LidarModel hdl64e();
// Velodyne VLP-16: 16 beams, -15..+15 deg, 0.2 deg azimuth at 10 Hz, 100 m.
LidarModel vlp16();
// Ouster OS1-64: 64 beams, +-16.6 deg, 1024 columns at 10 Hz, 120 m.
LidarModel os1_64();
// Looks a model up by name ("hdl64e", "vlp16", "os1-64"); throws std::invalid_argument.
LidarModel lidar_model_by_name(const std::string& name);

struct SimulatedScan {
  PointCloud points;             // in the sensor frame
  std::vector<uint32_t> labels;  // one SemanticKITTI label per point
};

// Simulates one revolution from pose T_world_sensor (all rays from one pose, i.e. a
// motion-compensated scan). Deterministic for a given seed. Single-threaded.
SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model,
                            const Pose3d& T_world_sensor, uint64_t seed);

// Scans at T_world_sensor[frames[k]] for every k, seeded with the frame index, simulated on
// `threads` threads (the calling thread included; < 2 means the calling thread only).
std::vector<SimulatedScan> simulate_scans(const RayCaster& caster, const LidarModel& model, const Poses& T_world_sensor,
                                          const std::vector<size_t>& frames, int threads);

}  // namespace segmatch::sim
