// LiDAR sensor models and scan simulation.
//
// Conventions: sensor frame x forward, y left, z up. Rays that are dropped or hit nothing
// produce no point; the others come out in the order the sensor emits them.
//
// Spinning models: column j has azimuth 2*pi*j/columns, counter-clockwise from +x (column 0
// looks along +x, columns/4 along +y). Beams are listed top-down (highest elevation first)
// for every model. A scan is emitted column by column, beam by beam within a column.
//
// Rosette models: ray k of a scan leaves at time t0 + k / point_rate_hz, where t0 is the
// pattern time the scan starts at (given, or derived from the seed). Its direction depends
// on that time only, so consecutive frames continue one pattern and never repeat it.
//
// Randomness: column j (rosette: block j of kRosetteBlock consecutive rays) uses its own
// stream Rng(mix_seed(seed, j)) and every ray draws the same two 64-bit words in the same
// order whether or not it hits (the first gives the dropout and intensity-noise uniforms,
// 32 bits each; the second the range-noise uniform, 53 bits, turned into a Gaussian by the
// inverse normal CDF). So the output is a pure function of (scene, model, pose, seed[, time]),
// and stays so if columns are ever simulated in parallel. Only IEEE arithmetic, sqrt, log,
// sin and cos are involved: bitwise reproducible on machines of the same kind (same libm).
#include "segmatch/sim/lidar.h"

#include "segmatch/core/detail/random.h"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <thread>

namespace segmatch::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;
// Rays of a rosette scan that share one random stream (the unit of parallel work, were the
// rays ever cast in parallel).
constexpr size_t kRosetteBlock = 256;
// A rosette scan seeded without a time starts somewhere in this much of its pattern.
constexpr double kRosettePatternSpanS = 3600.0;

// Inverse of the standard normal CDF for p in (0, 1): Wichura's algorithm AS241 (PPND16),
// relative accuracy ~1e-16. Deterministic (no trig) and needs one uniform per Gaussian;
// log/sqrt only in the tails (|p - 0.5| > 0.425, 15% of draws).
double inverse_normal_cdf(double p) {
  const double q = p - 0.5;
  if (std::fabs(q) <= 0.425) {
    const double r = 0.180625 - q * q;
    return q *
           (((((((2509.0809287301226727 * r + 33430.575583588128105) * r + 67265.770927008700853) * r +
                45921.953931549871457) *
                   r +
               13731.693765509461125) *
                  r +
              1971.5909503065514427) *
                 r +
             133.14166789178437745) *
                r +
            3.387132872796366608) /
           (((((((5226.495278852545925 * r + 28729.085735721942674) * r + 39307.89580009271061) * r +
                21213.794301586595867) *
                   r +
               5394.1960214247511077) *
                  r +
              687.1870074920579083) *
                 r +
             42.313330701600911252) *
                r +
            1.0);
  }
  double r = std::sqrt(-std::log(q < 0.0 ? p : 1.0 - p));
  double x;
  if (r <= 5.0) {
    r -= 1.6;
    x = (((((((7.7454501427834140764e-4 * r + 0.0227238449892691845833) * r + 0.24178072517745061177) * r +
             1.27045825245236838258) *
                r +
            3.64784832476320460504) *
               r +
           5.7694972214606914055) *
              r +
          4.6303378461565452959) *
             r +
         1.42343711074968357734) /
        (((((((1.05075007164441684324e-9 * r + 5.475938084995344946e-4) * r + 0.0151986665636164571966) * r +
             0.14810397642748007459) *
                r +
            0.68976733498510000455) *
               r +
           1.6763848301838038494) *
              r +
          2.05319162663775882187) *
             r +
         1.0);
  } else {
    r -= 5.0;
    x = (((((((2.01033439929228813265e-7 * r + 2.71155556874348757815e-5) * r + 0.0012426609473880784386) * r +
             0.026532189526576123093) *
                r +
            0.29656057182850489123) *
               r +
           1.7848265399172913358) *
              r +
          5.4637849111641143699) *
             r +
         6.6579046435011037772) /
        (((((((2.04426310338993978564e-15 * r + 1.4215117583164458887e-7) * r + 1.8463183175100546818e-5) * r +
             7.868691311456132591e-4) *
                r +
            0.0148753612908506148525) *
               r +
           0.13692988092273580531) *
              r +
          0.59983220655588793769) *
             r +
         1.0);
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

// The two words every ray draws, whether or not it hits (see the top of the file).
struct RayDraws {
  double u_drop;  // [0, 1)
  double u_int;   // [0, 1)
  uint64_t w2;    // range noise, used only on a hit
};

RayDraws draw_ray(Rng& rng) {
  const uint64_t w1 = rng.next_u64();
  const uint64_t w2 = rng.next_u64();
  return {static_cast<double>(w1 >> 32) * 0x1.0p-32, static_cast<double>(w1 & 0xFFFFFFFFu) * 0x1.0p-32, w2};
}

// Noisy range of a hit: Gaussian noise from a uniform in (0, 1), never 0 or 1.
double noisy_range(const RayHit& hit, double sigma, uint64_t w2) {
  const double u_noise = (static_cast<double>(w2 >> 11) + 0.5) * 0x1.0p-53;
  const double noise = sigma > 0.0 ? sigma * inverse_normal_cdf(u_noise) : 0.0;
  return std::max(0.0, static_cast<double>(hit.range_m) + noise);
}

// Reflectivity dimmed at grazing incidence, with +-10 % multiplicative noise, in [0, 1].
float return_intensity(const RayHit& hit, const Eigen::Vector3f& dir_w, double u_int) {
  const float cos_inc = std::fabs(hit.normal.dot(dir_w));
  const float intensity = hit.reflectivity * (0.3f + 0.7f * cos_inc) * static_cast<float>(0.9 + 0.2 * u_int);
  return std::min(1.0f, std::max(0.0f, intensity));
}

SimulatedScan simulate_spinning(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                                uint64_t seed) {
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

  RayHit hit;
  for (int col = 0; col < columns; ++col) {
    const double az = 2.0 * kPi * static_cast<double>(col) / static_cast<double>(columns);
    const double ca = std::cos(az), sa = std::sin(az);
    const Eigen::Vector3d horiz_w = R.col(0) * ca + R.col(1) * sa;  // R * (ca, sa, 0)
    Rng rng(mix_seed(seed, static_cast<uint64_t>(col)));
    for (size_t i = 0; i < beams; ++i) {
      const RayDraws d = draw_ray(rng);  // fixed draws per ray, independent of the outcome
      if (d.u_drop < model.dropout_probability) continue;

      const Eigen::Vector3f dir_w = (horiz_w * cos_el[i] + up_w * sin_el[i]).cast<float>();
      if (!caster.cast(origin, dir_w, model.min_range_m, model.max_range_m, &hit)) continue;
      const double range = noisy_range(hit, model.range_noise_sigma_m, d.w2);
      const double h = cos_el[i] * range;
      Point p;
      p.x = static_cast<float>(h * ca);
      p.y = static_cast<float>(h * sa);
      p.z = static_cast<float>(sin_el[i] * range);
      p.intensity = return_intensity(hit, dir_w, d.u_int);
      scan.points.push_back(p);
      scan.labels.push_back(hit.label);
    }
  }
  return scan;
}

// Unit direction (sensor frame) of a rosette ray at pattern time t_s. Each prism deflects
// the beam by a quarter of the field of view; the deflections add, so the beam reaches the
// rim when the prisms line up and the axis when they oppose.
Eigen::Vector3d rosette_direction(const RosetteConfig& r, double t_s) {
  auto phase = [](double hz, double t) {  // 2 pi frac(hz t): exact reduction before the trig
    const double turns = hz * t;
    return 2.0 * kPi * (turns - std::floor(turns));
  };
  const double p1 = phase(r.prism1_hz, t_s), p2 = phase(r.prism2_hz, t_s);
  const double a_h = 0.25 * r.fov_horizontal_deg * kDegToRad, a_v = 0.25 * r.fov_vertical_deg * kDegToRad;
  const double dh = a_h * (std::cos(p1) + std::cos(p2));  // towards +y
  const double dv = a_v * (std::sin(p1) + std::sin(p2));  // towards +z
  const double off_axis = std::sqrt(dh * dh + dv * dv);
  if (off_axis < 1e-12) return Eigen::Vector3d::UnitX();
  const double s = std::sin(off_axis) / off_axis;
  return {std::cos(off_axis), dh * s, dv * s};
}

SimulatedScan simulate_rosette(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                               uint64_t seed, double pattern_time_s) {
  SimulatedScan scan;
  const size_t rays = model.rays_per_scan();
  if (rays == 0) return scan;
  scan.points.reserve(rays);
  scan.labels.reserve(rays);
  const Eigen::Matrix3d R = T_world_sensor.linear();
  const Eigen::Vector3f origin = T_world_sensor.translation().cast<float>();
  const double ray_period_s = 1.0 / model.rosette.point_rate_hz;

  RayHit hit;
  Rng rng(0);
  for (size_t k = 0; k < rays; ++k) {
    if (k % kRosetteBlock == 0) rng = Rng(mix_seed(seed, static_cast<uint64_t>(k / kRosetteBlock)));
    const RayDraws d = draw_ray(rng);  // fixed draws per ray, independent of the outcome
    if (d.u_drop < model.dropout_probability) continue;

    const Eigen::Vector3d dir_s =
        rosette_direction(model.rosette, pattern_time_s + static_cast<double>(k) * ray_period_s);
    const Eigen::Vector3f dir_w = (R * dir_s).cast<float>();
    if (!caster.cast(origin, dir_w, model.min_range_m, model.max_range_m, &hit)) continue;
    const double range = noisy_range(hit, model.range_noise_sigma_m, d.w2);
    Point p;
    p.x = static_cast<float>(dir_s.x() * range);
    p.y = static_cast<float>(dir_s.y() * range);
    p.z = static_cast<float>(dir_s.z() * range);
    p.intensity = return_intensity(hit, dir_w, d.u_int);
    scan.points.push_back(p);
    scan.labels.push_back(hit.label);
  }
  return scan;
}

}  // namespace

size_t LidarModel::rays_per_scan() const {
  if (pattern == ScanPattern::kRosette) {
    if (!(rosette.point_rate_hz > 0.0) || !(rate_hz > 0.0f)) return 0;
    return static_cast<size_t>(std::llround(rosette.point_rate_hz / static_cast<double>(rate_hz)));
  }
  return elevations_deg.size() * static_cast<size_t>(std::max(0, columns));
}

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

LidarModel hdl32e() {
  LidarModel m;
  m.name = "hdl32e";
  m.elevations_deg = linspace_deg(10.67, -30.67, 32);       // 1.33 deg apart
  m.columns = static_cast<int>(std::lround(360.0 / 0.16));  // 2250 at 10 Hz
  m.min_range_m = 1.0f;
  m.max_range_m = 100.0f;
  m.range_noise_sigma_m = 0.02f;
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.73f;
  return m;
}

LidarModel os0_64() {
  LidarModel m;
  m.name = "os0-64";
  m.elevations_deg = linspace_deg(45.0, -45.0, 64);  // 1.43 deg apart
  m.columns = 1024;
  m.min_range_m = 0.5f;
  m.max_range_m = 50.0f;  // data sheet: 50 m at 80 % reflectivity, 35 m at 10 %
  m.range_noise_sigma_m = 0.03f;
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.5f;  // carried by hand or on a backpack
  return m;
}

LidarModel livox_avia() {
  LidarModel m;
  m.name = "livox-avia";
  m.pattern = ScanPattern::kRosette;
  m.rosette.fov_horizontal_deg = 70.4f;
  m.rosette.fov_vertical_deg = 77.2f;
  m.rosette.point_rate_hz = 240000.0;
  // 6 lasers x ~120 rev/s stand-in; the ratio is the golden section (the "most irrational"
  // number), so each new petal falls between earlier ones and frames interleave evenly.
  // About 116 petals per 0.1 s frame, ~200 rays each.
  m.rosette.prism1_hz = 720.0;
  m.rosette.prism2_hz = -720.0 * 0.6180339887498949;
  m.min_range_m = 1.0f;  // blind zone in front of the window
  m.max_range_m = 100.0f;
  m.range_noise_sigma_m = 0.02f;  // data sheet: 2 cm (1 sigma at 20 m)
  m.dropout_probability = 0.02f;
  m.rate_hz = 10.0f;
  m.mount_height_m = 1.0f;  // handheld or on a small platform
  return m;
}

LidarModel lidar_model_by_name(const std::string& name) {
  std::string key = name;
  std::transform(key.begin(), key.end(), key.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (key == "hdl64e") return hdl64e();
  if (key == "vlp16") return vlp16();
  if (key == "os1-64" || key == "os1_64") return os1_64();
  if (key == "hdl32e") return hdl32e();
  if (key == "os0-64" || key == "os0_64") return os0_64();
  if (key == "livox-avia" || key == "livox_avia" || key == "avia") return livox_avia();
  throw std::invalid_argument("unknown LiDAR model '" + name +
                              "'; valid names: hdl64e, hdl32e, vlp16, os1-64, os0-64, livox-avia");
}

SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                            uint64_t seed, double pattern_time_s) {
  if (model.pattern == ScanPattern::kRosette)
    return simulate_rosette(caster, model, T_world_sensor, seed, pattern_time_s);
  return simulate_spinning(caster, model, T_world_sensor, seed);
}

SimulatedScan simulate_scan(const RayCaster& caster, const LidarModel& model, const Pose3d& T_world_sensor,
                            uint64_t seed) {
  // A start anywhere in the first hour of the pattern, from a stream no ray uses.
  const double start_s = static_cast<double>(mix_seed(seed, 0x705e77e, 1) >> 11) * 0x1.0p-53 * kRosettePatternSpanS;
  return simulate_scan(caster, model, T_world_sensor, seed, start_s);
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
