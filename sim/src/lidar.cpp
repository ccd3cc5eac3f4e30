// Spinning LiDAR sensor models and scan simulation.
//
// Conventions: sensor frame x forward, y left, z up. Column j has azimuth 2*pi*j/columns,
// counter-clockwise from +x (column 0 looks along +x, columns/4 along +y). Beams are listed
// top-down (highest elevation first) for every model. A scan is emitted column by column,
// beam by beam within a column (like a real sensor stream); rays that are dropped or hit
// nothing produce no point.
//
// Randomness: column j uses its own stream Rng(mix_seed(seed, j)) and every ray draws the
// same two 64-bit words in the same order whether or not it hits (the first gives the
// dropout and intensity-noise uniforms, 32 bits each; the second the range-noise uniform,
// 53 bits, turned into a Gaussian by the inverse normal CDF). So the output is a pure
// function of (scene, model, pose, seed), and stays so if columns are ever simulated in
// parallel. Only IEEE arithmetic, sqrt and log are involved: bitwise reproducible on
// machines of the same kind (same libm).
#include "segmatch/sim/lidar.h"

#include "segmatch/core/random.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace segmatch::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Inverse of the standard normal CDF for p in (0, 1): Wichura's algorithm AS241 (PPND16),
// relative accuracy ~1e-16. Deterministic (no trig) and needs one uniform per Gaussian;
// log/sqrt only in the tails (|p - 0.5| > 0.425, 15% of draws).
double inverse_normal_cdf(double p) {
  const double q = p - 0.5;
  if (std::fabs(q) <= 0.425) {
    const double r = 0.180625 - q * q;
    return q *
           (((((((2509.0809287301226727 * r + 33430.575583588128105) * r +
                 67265.770927008700853) * r + 45921.953931549871457) * r +
               13731.693765509461125) * r + 1971.5909503065514427) * r +
             133.14166789178437745) * r + 3.387132872796366608) /
           (((((((5226.495278852545925 * r + 28729.085735721942674) * r +
                 39307.89580009271061) * r + 21213.794301586595867) * r +
               5394.1960214247511077) * r + 687.1870074920579083) * r +
             42.313330701600911252) * r + 1.0);
  }
  double r = std::sqrt(-std::log(q < 0.0 ? p : 1.0 - p));
  double x;
  if (r <= 5.0) {
    r -= 1.6;
    x = (((((((7.7454501427834140764e-4 * r + 0.0227238449892691845833) * r +
              0.24178072517745061177) * r + 1.27045825245236838258) * r +
            3.64784832476320460504) * r + 5.7694972214606914055) * r +
          4.6303378461565452959) * r + 1.42343711074968357734) /
        (((((((1.05075007164441684324e-9 * r + 5.475938084995344946e-4) * r +
              0.0151986665636164571966) * r + 0.14810397642748007459) * r +
            0.68976733498510000455) * r + 1.6763848301838038494) * r +
          2.05319162663775882187) * r + 1.0);
  } else {
    r -= 5.0;
    x = (((((((2.01033439929228813265e-7 * r + 2.71155556874348757815e-5) * r +
              0.0012426609473880784386) * r + 0.026532189526576123093) * r +
            0.29656057182850489123) * r + 1.7848265399172913358) * r +
          5.4637849111641143699) * r + 6.6579046435011037772) /
        (((((((2.04426310338993978564e-15 * r + 1.4215117583164458887e-7) * r +
              1.8463183175100546818e-5) * r + 7.868691311456132591e-4) * r +
            0.0148753612908506148525) * r + 0.13692988092273580531) * r +
          0.59983220655588793769) * r + 1.0);
  }
  return q < 0.0 ? -x : x;
}

std::vector<float> linspace_deg(double from, double to, int n) {
  std::vector<float> out(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    const double f = n > 1 ? static_cast<double>(i) / (n - 1) : 0.0;
    out[static_cast<size_t>(i)] = static_cast<float>(from + (to - from) * f);
  }
  return out;
}

}  // namespace

LidarModel hdl64e() {
  LidarModel m;
  m.name = "hdl64e";
  // Upper block: 32 lasers +2.0 .. -8.33 deg; lower block: 32 lasers -8.83 .. -24.9 deg.
  m.elevations_deg = linspace_deg(2.0, -8.33, 32);
  const std::vector<float> lower = linspace_deg(-8.83, -24.9, 32);
  m.elevations_deg.insert(m.elevations_deg.end(), lower.begin(), lower.end());
  m.columns = static_cast<int>(std::lround(360.0 / 0.17));  // 2118
  m.min_range_m = 0.9f;
  m.max_range_m = 120.0f;
  m.range_noise_sigma_m = 0.02f;
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.73f;
  return m;
}

LidarModel vlp16() {
  LidarModel m;
  m.name = "vlp16";
  m.elevations_deg = linspace_deg(15.0, -15.0, 16);  // 2 deg apart
  m.columns = 1800;
  m.min_range_m = 0.9f;
  m.max_range_m = 100.0f;
  m.range_noise_sigma_m = 0.03f;
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.73f;
  return m;
}

LidarModel os1_64() {
  LidarModel m;
  m.name = "os1-64";
  m.elevations_deg = linspace_deg(16.6, -16.6, 64);
  m.columns = 1024;
  m.min_range_m = 0.8f;
  m.max_range_m = 120.0f;
  m.range_noise_sigma_m = 0.03f;
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.73f;
  return m;
}

LidarModel lidar_model_by_name(const std::string& name) {
  std::string key = name;
  std::transform(key.begin(), key.end(), key.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (key == "hdl64e") return hdl64e();
  if (key == "vlp16") return vlp16();
  if (key == "os1-64" || key == "os1_64") return os1_64();
  throw std::invalid_argument("unknown LiDAR model '" + name +
                              "'; valid names: hdl64e, vlp16, os1-64");
}

SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model,
                            const Pose3d& T_world_sensor, uint64_t seed) {
  SimulatedScan scan;
  const size_t beams = model.elevations_deg.size();
  const int columns = model.columns;
  if (beams == 0 || columns <= 0) return scan;
  scan.points.reserve(model.rays_per_scan());
  scan.labels.reserve(model.rays_per_scan());

  // Trig once per beam and once per column, never per ray.
  std::vector<double> cos_el(beams), sin_el(beams);
  for (size_t i = 0; i < beams; ++i) {
    const double el = static_cast<double>(model.elevations_deg[i]) * kPi / 180.0;
    cos_el[i] = std::cos(el);
    sin_el[i] = std::sin(el);
  }
  const Eigen::Matrix3d R = T_world_sensor.linear();
  const Eigen::Vector3d up_w = R.col(2);
  const Eigen::Vector3f origin = T_world_sensor.translation().cast<float>();
  const float min_range = model.min_range_m;
  const float max_range = model.max_range_m;
  const double sigma = model.range_noise_sigma_m;
  const double dropout = model.dropout_probability;

  RayHit hit;
  for (int col = 0; col < columns; ++col) {
    const double az = 2.0 * kPi * static_cast<double>(col) / static_cast<double>(columns);
    const double ca = std::cos(az), sa = std::sin(az);
    const Eigen::Vector3d horiz_w = R.col(0) * ca + R.col(1) * sa;  // R * (ca, sa, 0)
    Rng rng(mix_seed(seed, static_cast<uint64_t>(col)));
    for (size_t i = 0; i < beams; ++i) {
      // Fixed draws per ray, independent of the outcome.
      const uint64_t w1 = rng.next_u64();
      const uint64_t w2 = rng.next_u64();
      const double u_drop = static_cast<double>(w1 >> 32) * 0x1.0p-32;         // [0, 1)
      const double u_int = static_cast<double>(w1 & 0xFFFFFFFFu) * 0x1.0p-32;  // [0, 1)
      if (u_drop < dropout) continue;

      const Eigen::Vector3f dir_w = (horiz_w * cos_el[i] + up_w * sin_el[i]).cast<float>();
      if (!caster.cast(origin, dir_w, min_range, max_range, &hit)) continue;

      // Gaussian range noise; the uniform is in (0, 1), never 0 or 1.
      const double u_noise = (static_cast<double>(w2 >> 11) + 0.5) * 0x1.0p-53;
      const double noise = sigma > 0.0 ? sigma * inverse_normal_cdf(u_noise) : 0.0;
      const double range = std::max(0.0, static_cast<double>(hit.range_m) + noise);
      const double h = cos_el[i] * range;

      const float cos_inc = std::fabs(hit.normal.dot(dir_w));
      float intensity = hit.reflectivity * (0.3f + 0.7f * cos_inc) *
                        static_cast<float>(0.9 + 0.2 * u_int);
      intensity = std::min(1.0f, std::max(0.0f, intensity));

      Point p;
      p.x = static_cast<float>(h * ca);
      p.y = static_cast<float>(h * sa);
      p.z = static_cast<float>(sin_el[i] * range);
      p.intensity = intensity;
      scan.points.push_back(p);
      scan.labels.push_back(hit.label);
    }
  }
  return scan;
}

std::vector<SimulatedScan> simulate_scans(const RayCaster& caster, const LidarModel& model, const Poses& T_world_sensor,
                                          const std::vector<size_t>& frames, int threads) {
  std::vector<SimulatedScan> scans(frames.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k; (k = next++) < frames.size();)
      scans[k] = simulate_scan(caster, model, T_world_sensor[frames[k]], frames[k]);
  };
  std::vector<std::thread> pool;
  for (int i = 1; i < threads; ++i) pool.emplace_back(work);
  work();
  for (auto& th : pool) th.join();
  return scans;
}

}  // namespace segmatch::sim
