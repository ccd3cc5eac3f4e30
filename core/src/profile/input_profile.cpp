#include "segmatch/core/profile/input_profile.h"
#include "detail/seg_grid.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace segmatch {
namespace {

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(p * static_cast<double>(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// The points of a cloud bucketed in cells of cell_m (the core's CellGrid): the distance from a
// point to its nearest cloud point, when that is within one cell (both measurements below only
// ask about short distances: the spacing of a scan, and whether a point of another scan lies
// near). Non-finite cloud points are in no cell; they were never nearer than anything.
class PointGrid {
 public:
  PointGrid(const PointCloud& cloud, double cell_m)
      : cloud_(cloud), cell_m_(cell_m), grid_(detail::CellGrid::build(cloud, cell_m, false, "input profile cell")) {}
  // Distance to the nearest cloud point other than index `skip`, capped at cell_m. The cell of
  // p first; a neighbour cell is read only if its box comes nearer than the best so far (the
  // minimum is the same, dense scans hold hundreds of points per cell).
  double nearest(const Eigen::Vector3f& p, uint32_t skip = UINT32_MAX) const {
    double best = cell_m_;
    int64_t c[3];
    if (!cell_of(p, c)) return best;
    double inside[3];  // p's offset inside its cell, in metres
    for (int a = 0; a < 3; ++a) inside[a] = double(p[a]) - double(c[a] + grid_.frame.base[a]) * cell_m_;
    visit(c, [&](int dx, int dy, int dz, uint32_t cell) {
      const int d[3] = {dx, dy, dz};
      double gap2 = 0;  // squared distance from p to the neighbour cell's box
      for (int a = 0; a < 3; ++a) {
        const double g = d[a] < 0 ? inside[a] : d[a] > 0 ? cell_m_ - inside[a] : 0.0;
        if (d[a] != 0) gap2 += g * g;
      }
      if (gap2 > best * best * (1 + 1e-5) + 1e-12) return false;  // margin: float distances, double box
      for (uint32_t k = grid_.begin[cell]; k < grid_.begin[cell + 1]; ++k) {
        const uint32_t i = grid_.order[k];
        if (i != skip) best = std::min(best, static_cast<double>((cloud_[i].xyz() - p).norm()));
      }
      return false;
    });
    return best;
  }
  // Whether a cloud point lies nearer than cell_m to p (nearest(p) < cell_m, stopping at the first).
  bool any_within(const Eigen::Vector3f& p) const {
    int64_t c[3];
    if (!cell_of(p, c)) return false;
    return visit(c, [&](int, int, int, uint32_t cell) {
      for (uint32_t k = grid_.begin[cell]; k < grid_.begin[cell + 1]; ++k)
        if (static_cast<double>((cloud_[grid_.order[k]].xyz() - p).norm()) < cell_m_) return true;
      return false;
    });
  }

 private:
  bool cell_of(const Eigen::Vector3f& p, int64_t c[3]) const {
    for (int a = 0; a < 3; ++a) {
      const double q = std::floor(double(p[a]) / cell_m_);
      if (!(std::abs(q) < 1e15)) return false;  // not finite, or far outside any cloud
      c[a] = static_cast<int64_t>(q) - grid_.frame.base[a];
    }
    return true;
  }
  // Calls f(dx, dy, dz, cell) for the occupied cells around c, c itself first, until f is true.
  template <typename F>
  bool visit(const int64_t c[3], F&& f) const {
    const uint32_t self = grid_.cell_at(c[0], c[1], c[2]);
    if (self != detail::FlatHashMap::kMissing && f(0, 0, 0, self)) return true;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          const uint32_t cell = grid_.cell_at(c[0] + dx, c[1] + dy, c[2] + dz);
          if (cell != detail::FlatHashMap::kMissing && f(dx, dy, dz, cell)) return true;
        }
    return false;
  }

  const PointCloud& cloud_;
  double cell_m_;
  detail::CellGrid grid_;
};

// Every step-th index of n things, at most `sample` of them.
size_t stride_for(size_t n, size_t sample) { return std::max<size_t>(1, n / std::max<size_t>(1, sample)); }

// Nearest-neighbour distances (capped at 1 m) of up to n evenly strided points of a scan.
std::vector<double> nearest_neighbour_distances(const PointCloud& scan, size_t n,
                                                std::vector<double>* ranges_of_sampled) {
  const PointGrid grid(scan, 1.0);
  std::vector<double> out;
  const size_t step = stride_for(scan.size(), n);
  for (size_t i = 0; i < scan.size(); i += step) {
    out.push_back(grid.nearest(scan[i].xyz(), static_cast<uint32_t>(i)));
    if (ranges_of_sampled) ranges_of_sampled->push_back(scan[i].xyz().norm());
  }
  return out;
}

}  // namespace

double pose_agreement(const PointCloud& a, const Pose3d& T_world_a, const PointCloud& b, const Pose3d& T_world_b,
                      double radius_m, size_t sample) {
  if (a.empty() || b.empty()) return 0.0;
  // The sampled points of b, put in a's frame, against a.
  const Eigen::Isometry3f T_a_b = (T_world_a.inverse() * T_world_b).cast<float>();
  const PointGrid grid(a, radius_m);
  const size_t step = stride_for(b.size(), sample);
  size_t probes = 0, near = 0;
  for (size_t i = 0; i < b.size(); i += step, ++probes) near += grid.any_within(T_a_b * b[i].xyz());
  return static_cast<double>(near) / static_cast<double>(probes);
}

void check_pose_agreement(const std::vector<ScanPair>& pairs, InputMeasurements& m) {
  for (const ScanPair& p : pairs) {
    if ((p.T_world_a.translation() - p.T_world_b.translation()).norm() >= InputMeasurements::kAgreementMaxDistanceM)
      continue;
    ++m.pairs_checked;
    if (pose_agreement(*p.a, p.T_world_a, *p.b, p.T_world_b, InputMeasurements::kAgreementRadiusM) <
        InputMeasurements::kMinAgreement) {
      ++m.pairs_disagreeing;
      m.disagreeing_pairs.push_back(p.index_a);
    }
  }
}

Rings measure_rings(std::vector<double> e) {
  Rings r;
  if (e.size() < 100) return r;
  std::sort(e.begin(), e.end());
  const size_t min_points =
      std::max<size_t>(3, static_cast<size_t>(InputMeasurements::kRingMinShare * double(e.size())));
  std::vector<double> centres;
  size_t held = 0;
  for (size_t begin = 0; begin < e.size();) {
    size_t end = begin + 1;
    while (end < e.size() && e[end] - e[end - 1] <= InputMeasurements::kRingGapDeg) ++end;
    if (end - begin >= min_points && e[end - 1] - e[begin] <= InputMeasurements::kRingMaxWidthDeg) {
      centres.push_back(e[(begin + end) / 2]);
      held += end - begin;
    }
    begin = end;
  }
  r.count = centres.size();
  r.share = double(held) / double(e.size());
  r.centres_deg = centres;
  if (centres.size() < 2) return r;
  std::vector<double> steps;
  for (size_t k = 1; k < centres.size(); ++k) steps.push_back(centres[k] - centres[k - 1]);
  r.spacing_deg = percentile(steps, 0.5);
  r.lowest_deg = centres.front(), r.highest_deg = centres.back();
  r.bottom_step_deg = steps.front(), r.top_step_deg = steps.back();
  return r;
}

double Rings::count_between(double lo_deg, double hi_deg) const {
  if (count < 2) return double(count);
  const double below = bottom_step_deg > 0 ? std::max(0.0, std::round((lowest_deg - lo_deg) / bottom_step_deg)) : 0.0;
  const double above = top_step_deg > 0 ? std::max(0.0, std::round((hi_deg - highest_deg) / top_step_deg)) : 0.0;
  return double(count) + below + above;
}

std::string InputMeasurements::beam_layout() const {
  if (!wide_fov) return "narrow-fov";
  if (downsampled) return "slam keyframes";
  if (elevation_max_deg - elevation_min_deg >= kWideElevationDeg) return "wide-fov spinning";
  if (ring_count <= 0) return "spinning, rings not resolved";
  if (ring_count <= 20) return "16-beam spinning";
  if (ring_count <= 40) return "32-beam spinning";
  return "64/128-beam spinning";
}

std::string InputMeasurements::sensor_class() const {
  if (!wide_fov) return "narrow-fov";
  return downsampled ? "sparse-spinning" : "dense-spinning";
}

void InputProfileConfig::validate() const {
  if (max_scans == 0) throw std::invalid_argument("max_scans must be > 0");
  if (sample_points == 0) throw std::invalid_argument("sample_points must be > 0");
}

std::vector<size_t> scans_to_measure(size_t count, const InputProfileConfig& config) {
  std::vector<size_t> out;
  if (count == 0) return out;
  const size_t n = std::min(count, config.max_scans);
  for (size_t k = 0; k < n; ++k) out.push_back(n == 1 ? 0 : k * (count - 1) / (n - 1));
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

ElevationBand measure_elevations(const PointCloud& cloud, const Eigen::Vector3f& sensor, size_t sample) {
  const size_t stride = std::max<size_t>(1, cloud.size() / std::max<size_t>(1, sample));
  std::vector<double> elevation;
  elevation.reserve(cloud.size() / stride + 1);
  for (size_t i = 0; i < cloud.size(); i += stride) {
    const Eigen::Vector3f d = cloud[i].xyz() - sensor;
    const double r = d.norm();
    if (!(r > 0.1) || !std::isfinite(r)) continue;
    elevation.push_back(std::atan2(double(d.z()), std::hypot(double(d.x()), double(d.y()))) * 180.0 / M_PI);
  }
  if (elevation.empty()) return {};
  return {percentile(elevation, 0.01), percentile(elevation, 0.99)};
}

InputMeasurements measure_input(const std::vector<PointCloud>& scans, const Poses& T_world_sensor,
                                const InputProfileConfig& config) {
  config.validate();
  if (scans.empty()) throw std::invalid_argument("measure_input: no scans");
  constexpr double kRadToDeg = 180.0 / M_PI;
  std::vector<double> points, coverage, el_lo, el_hi, r50, r95, spacing, per_range, steps, rings, ring_steps,
      ring_shares;
  for (size_t s = 0; s < scans.size(); ++s) {
    const PointCloud& scan = scans[s];
    if (scan.size() < 10) continue;
    std::vector<bool> bins(360, false);
    std::vector<double> elevation, range, far_elevation;
    elevation.reserve(scan.size()), range.reserve(scan.size());
    for (const Point& p : scan) {
      const double r = p.xyz().norm(), rxy = std::hypot(p.x, p.y);
      if (!(r > 0.1) || !std::isfinite(r)) continue;
      range.push_back(r);
      elevation.push_back(std::atan2(p.z, rxy) * kRadToDeg);
      if (r >= InputMeasurements::kRingMinRangeM) far_elevation.push_back(elevation.back());
      const int bin = static_cast<int>(std::floor(std::atan2(p.y, p.x) * kRadToDeg + 180.0)) % 360;
      bins[static_cast<size_t>(std::max(0, bin))] = true;
    }
    if (range.size() < 10) continue;
    points.push_back(static_cast<double>(scan.size()));
    coverage.push_back(static_cast<double>(std::count(bins.begin(), bins.end(), true)) / 360.0);
    el_lo.push_back(percentile(elevation, 0.01));
    el_hi.push_back(percentile(elevation, 0.99));
    r50.push_back(percentile(range, 0.5));
    r95.push_back(percentile(range, 0.95));
    const Rings found = measure_rings(std::move(far_elevation));
    rings.push_back(found.count_between(percentile(elevation, 0.01), percentile(elevation, 0.99)));
    ring_steps.push_back(found.spacing_deg);
    ring_shares.push_back(found.share);
    std::vector<double> ranges;
    const std::vector<double> nn = nearest_neighbour_distances(scan, config.sample_points, &ranges);
    spacing.insert(spacing.end(), nn.begin(), nn.end());
    for (size_t i = 0; i < nn.size(); ++i)
      if (ranges[i] > 1.0 && nn[i] < 1.0) per_range.push_back(nn[i] / ranges[i]);
  }
  if (points.empty()) throw std::invalid_argument("measure_input: no scan holds 10 finite points");
  for (size_t s = 1; s < T_world_sensor.size(); ++s)
    steps.push_back((T_world_sensor[s].translation() - T_world_sensor[s - 1].translation()).norm());
  InputMeasurements m;
  m.scans_measured = points.size();
  m.points_per_scan = percentile(points, 0.5);
  m.azimuth_coverage = percentile(coverage, 0.5);
  m.elevation_min_deg = percentile(el_lo, 0.5);
  m.elevation_max_deg = percentile(el_hi, 0.5);
  m.range_p50_m = percentile(r50, 0.5);
  m.range_p95_m = percentile(r95, 0.5);
  m.spacing_p10_m = percentile(spacing, 0.1);
  m.spacing_p50_m = percentile(spacing, 0.5);
  m.spacing_per_range = percentile(per_range, 0.5);
  m.scan_distance_m = percentile(steps, 0.5);
  m.downsampled = m.spacing_p10_m >= InputMeasurements::kDownsampledSpacingM;
  m.wide_fov = m.azimuth_coverage >= InputMeasurements::kWideFovCoverage;
  // Rings are a raw scan's (Rings::count_between: the steep ones near the ground count too).
  if (!m.downsampled && percentile(ring_shares, 0.5) >= InputMeasurements::kRingsResolvedShare &&
      percentile(rings, 0.5) >= 2) {
    m.ring_count = percentile(rings, 0.5);
    m.ring_spacing_deg = percentile(ring_steps, 0.5);
  }
  return m;
}

}  // namespace segmatch
