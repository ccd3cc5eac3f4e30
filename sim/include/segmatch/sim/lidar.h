// LiDAR sensor models (spinning multi-beam and rosette-scanning solid state) and scan
// simulation.
#pragma once

#include "segmatch/core/common/types.h"
#include "segmatch/sim/raycaster.h"

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch::sim {

// How a model sweeps its rays.
enum class ScanPattern {
  kSpinning,  // beams at fixed elevations, rotating about +z (Velodyne, Ouster)
  kRosette,   // one beam steered by two counter-rotating prisms (Livox): a flower pattern
              // in a forward cone that never repeats, so coverage grows with integration time
};

// Rosette (Risley prism) scanning. The beam's deflection from +x is the sum of two equal
// vectors turning at prism1_hz and prism2_hz (opposite signs, irrational ratio): a rose
// whose petals all pass through the axis, denser in the centre than at the rim, rotated a
// little further every petal so it never closes on itself.
struct RosetteConfig {
  float fov_horizontal_deg = 70.4f;  // full width of the field of view
  float fov_vertical_deg = 77.2f;    // full height (the cone is slightly elliptic)
  double point_rate_hz = 240000.0;   // rays per second (0.1 s frame: 24000 rays)
  double prism1_hz = 0.0;            // revolutions per second of the first prism
  double prism2_hz = 0.0;            // of the second, counter-rotating (negative)
};

struct LidarModel {
  std::string name;
  ScanPattern pattern = ScanPattern::kSpinning;
  std::vector<float> elevations_deg;  // spinning: one per beam
  int columns = 0;                    // spinning: azimuth steps per revolution
  RosetteConfig rosette;              // rosette only
  float min_range_m = 0.9f;
  float max_range_m = 120.0f;
  float range_noise_sigma_m = 0.02f;  // Gaussian range noise
  float dropout_probability = 0.02f;  // returns lost at random
  float rate_hz = 10.0f;              // scans (frames) per second
  float mount_height_m = 1.73f;       // sensor height above the ground it stands on

  size_t rays_per_scan() const;
};

// Velodyne HDL-64E (KITTI): 64 beams, -24.9..+2.0 deg, 0.17 deg azimuth at 10 Hz, 120 m.
LidarModel hdl64e();
// Velodyne VLP-16: 16 beams, -15..+15 deg, 0.2 deg azimuth at 10 Hz, 100 m.
LidarModel vlp16();
// Ouster OS1-64: 64 beams, +-16.6 deg, 1024 columns at 10 Hz, 120 m.
LidarModel os1_64();
// Velodyne HDL-32E: 32 beams, -30.67..+10.67 deg (1.33 deg apart), 0.16 deg azimuth at 10 Hz,
// 100 m.
LidarModel hdl32e();
// Ouster OS0-64: 64 beams, +-45 deg (wide field of view), 1024 columns at 10 Hz, 50 m, carried
// at 1.5 m (by hand or on a backpack).
LidarModel os0_64();
// Livox Avia: rosette in a 70.4 x 77.2 deg forward cone (+x), 240k points/s (24000 per
// 0.1 s frame), 100 m (the scene limits it; ~190 m at 10 % reflectivity in the data sheet),
// handheld at 1.0 m. The Avia's six lasers (40k points/s each) are modelled as one beam
// whose prisms turn six times faster, which puts as many petals into a frame.
LidarModel livox_avia();
// Looks a model up by name ("hdl64e", "hdl32e", "vlp16", "os1-64", "os0-64", "livox-avia"); throws
// std::invalid_argument.
LidarModel lidar_model_by_name(const std::string& name);

struct SimulatedScan {
  PointCloud points;             // in the sensor frame
  std::vector<uint32_t> labels;  // one SemanticKITTI label per point
};

// Simulates one scan (a revolution, or 1 / rate_hz of a rosette) from pose T_world_sensor
// (all rays from one pose, i.e. a motion-compensated scan). Deterministic for a given seed.
// Single-threaded. A rosette starts at a point of its endless pattern derived from the seed.
SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                            uint64_t seed);
// The same with the rosette's start given: pattern_time_s is the time since the prisms were
// at phase zero, so scans at t, t + 1 / rate_hz, ... continue one another like the frames
// of a recording. Spinning models ignore it.
SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                            uint64_t seed, double pattern_time_s);

// Scans at T_world_sensor[frames[k]] for every k, seeded with the frame index, simulated on
// `threads` threads (the calling thread included; < 2 means the calling thread only).
std::vector<SimulatedScan> simulate_scans(const RayCaster& caster, const LidarModel& model, const Poses& T_world_sensor,
                                          const std::vector<size_t>& frames, int threads);

}  // namespace segmatch::sim
