// Range-image segmentation of one raw scan: Bogoslavskyi & Stachniss, "Fast range image-based
// segmentation of sparse 3D laser scans for online operation", IROS 2016.
//
// A spinning LiDAR measures a grid: one row per laser (ring), one column per firing. Neighbours
// in that grid are neighbours on the sensor's sphere, so two objects that touch in 3-D but lie
// at different ranges are told apart by the angle beta (paper III, Fig. 3): for neighbouring
// beams with ranges d1 >= d2 and angle alpha between them,
//   beta = atan2(d2 sin(alpha), d1 - d2 cos(alpha)),
// the angle at the nearer point between its beam and the line to the farther point. A surface
// seen across both beams gives a large beta, a depth jump a small one; pixels with
// beta > threshold (10 deg) join one component (paper III-B, breadth-first search on N4).
//
// Our clouds carry no ring or column per point, so the grid is recovered (fit_range_image):
//   1. the rings' axis: a scan in an odometry or map frame is tilted by the vehicle's pitch
//      and roll, which spreads every ring over a band of elevations; the axis that makes the
//      elevations sharpest (coarse to fine search) is the sensor's;
//   2. rows: the rings of the elevations about that axis (measure_rings, as the input profile
//      counts them), extended by their step beyond the outermost ones (steep rings meet the
//      ground too near to be measured);
//   3. columns: the median azimuth step between neighbouring points of a ring, and per ring
//      the phase of its firings (lasers of one head fire at slightly different azimuths).
// Beyond the paper, alpha is the actual angle between the two points' beams rather than the
// sensor's nominal step, so rows of uneven spacing (HDL-64E's two blocks) need no table.
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "detail/seg_grid.h"
#include "segmatch/core/profile/input_profile.h"
#include "segmentation/seg_segmenters.h"

namespace segmatch {
namespace {

constexpr double kDeg = M_PI / 180.0;
constexpr int kMinFitPoints = 100;  // fewer far points: no rings can be told (measure_rings)
constexpr size_t kAxisSamples = 2000;
constexpr size_t kRingSamples = 30000;
constexpr float kMinStepDeg = 0.05f;  // validate()'s floor, also for a measured step

// Up to n items spread over v, one from each of n equal strides at a pseudo-random place in it:
// scans are stored column by column, and a plain stride that is a multiple of the ring count
// would sample one ring only.
template <typename T>
std::vector<T> spread_sample(const std::vector<T>& v, size_t n) {
  if (v.size() <= n) return v;
  const size_t stride = v.size() / n;
  std::vector<T> out(n);
  for (size_t k = 0; k < n; ++k) out[k] = v[k * stride + (k * 2654435761u) % stride];
  return out;
}

// Unit vector and range of every point from the sensor (range 0: not finite or at the sensor).
struct Beams {
  std::vector<Eigen::Vector3f> dir;
  std::vector<float> range;
};

Beams beams_of(const PointCloud& cloud, const Eigen::Vector3f& sensor) {
  Beams b;
  b.dir.resize(cloud.size(), Eigen::Vector3f::Zero());
  b.range.resize(cloud.size(), 0.0f);
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f d = cloud[i].xyz() - sensor;
    const float r = d.norm();
    if (!(r > 1e-3f) || !std::isfinite(r)) continue;
    b.dir[i] = d / r;
    b.range[i] = r;
  }
  return b;
}

// The axis tilted by (a, b) radians from z towards x and y.
Eigen::Vector3f tilted_axis(double a, double b) {
  return Eigen::Vector3d(std::tan(a), std::tan(b), 1.0).normalized().cast<float>();
}

// How sharp the elevations about `axis` are: the sum of squared counts of bins 0.05 deg high
// (at the horizon; binned by sine, which is monotonic and spares an asin per point), twice,
// the second grid shifted by half a bin, so that a ring on a bin edge scores as one inside.
// Summed as each point's count of earlier points in its bins, (sum n^2 - N) / 2: the same order.
constexpr double kSineBin = 0.05 * kDeg;
int64_t sharpness(const std::vector<Eigen::Vector3f>& dirs, const Eigen::Vector3f& axis, std::vector<int>& bins,
                  std::vector<uint32_t>& keys) {
  const float per_bin = float(1.0 / kSineBin);
  int64_t score = 0;
  keys.resize(dirs.size());
  for (size_t k = 0; k < dirs.size(); ++k) {
    const float s = (std::min(std::max(dirs[k].dot(axis), -1.0f), 1.0f) + 1.0f) * per_bin;
    const uint32_t a = uint32_t(s) * 2, b = uint32_t(s + 0.5f) * 2 + 1;  // < 2^16
    score += bins[a]++;
    score += bins[b]++;
    keys[k] = a | b << 16;
  }
  for (const uint32_t key : keys) bins[key & 0xFFFF] = bins[key >> 16] = 0;
  return score;
}

// The rings' axis: tilts up to 8 deg in 0.25-deg steps, then 0.05 and 0.01 around the best.
// A vehicle on a 4 % grade pitches 2.3 deg, so queries in an odometry frame tilt by up to twice
// that against the frame's first scan; the ring steps are 0.3 .. 2 deg. The coarse search, most
// of the candidates, looks at a quarter of the beams: a few per ring still tell sharp from smeared.
Eigen::Vector3f rings_axis(const std::vector<Eigen::Vector3f>& all) {
  std::vector<Eigen::Vector3f> quarter;
  for (size_t k = 0; k < all.size(); k += 4) quarter.push_back(all[k]);
  std::vector<int> bins(size_t(2.0 / kSineBin + 2.0) * 2, 0);
  std::vector<uint32_t> keys;
  double best_a = 0.0, best_b = 0.0;
  int64_t best = 0;
  for (const auto& [step, reach] : {std::pair{0.25, 8.0}, std::pair{0.05, 0.3}, std::pair{0.01, 0.05}}) {
    const std::vector<Eigen::Vector3f>& dirs = step == 0.25 ? quarter : all;
    best = sharpness(dirs, tilted_axis(best_a, best_b), bins, keys);
    const double ca = best_a, cb = best_b;
    const int n = int(std::lround(reach / step));
    for (int i = -n; i <= n; ++i) {
      for (int j = -n; j <= n; ++j) {
        const double a = ca + i * step * kDeg, b = cb + j * step * kDeg;
        const int64_t s = sharpness(dirs, tilted_axis(a, b), bins, keys);
        if (s > best) best = s, best_a = a, best_b = b;
      }
    }
  }
  return tilted_axis(best_a, best_b);
}

// The frame whose z is `axis` and whose x is the scan frame's x projected across it.
Eigen::Matrix3f image_frame(const Eigen::Vector3f& axis) {
  Eigen::Vector3f x = Eigen::Vector3f::UnitX() - axis * axis.x();
  if (x.norm() < 1e-3f) x = Eigen::Vector3f::UnitY() - axis * axis.y();
  x.normalize();
  Eigen::Matrix3f m;
  m.row(0) = x;
  m.row(1) = axis.cross(x);
  m.row(2) = axis;
  return m;
}

double elevation_deg(const Eigen::Vector3f& d) { return std::asin(std::clamp(double(d.z()), -1.0, 1.0)) / kDeg; }
double azimuth_deg(const Eigen::Vector3f& d) {
  const double a = std::atan2(double(d.y()), double(d.x())) / kDeg;
  return a < 0.0 ? a + 360.0 : a;
}

// Row bounds: midway between the rings, and beyond the outermost ones further rings at the
// step next to them, down to lo_deg and up to hi_deg. Empty if the elevations show no rings.
std::vector<float> ring_bounds(const std::vector<double>& far_elevations, double lo_deg, double hi_deg) {
  const Rings rings = measure_rings(far_elevations);
  if (rings.count < 2 || rings.share < InputMeasurements::kRingsResolvedShare) return {};
  std::vector<double> c = rings.centres_deg;
  while (c.front() - rings.bottom_step_deg > lo_deg - 0.5 * rings.bottom_step_deg)
    c.insert(c.begin(), c.front() - rings.bottom_step_deg);
  while (c.back() + rings.top_step_deg < hi_deg + 0.5 * rings.top_step_deg) c.push_back(c.back() + rings.top_step_deg);
  std::vector<float> bounds{float(c.front() - 0.5 * rings.bottom_step_deg)};
  for (size_t k = 1; k < c.size(); ++k) bounds.push_back(float(0.5 * (c[k - 1] + c[k])));
  bounds.push_back(float(c.back() + 0.5 * rings.top_step_deg));
  return bounds;
}

int row_of(const std::vector<float>& bounds, double elevation) {
  const auto it = std::upper_bound(bounds.begin(), bounds.end(), float(elevation));
  if (it == bounds.begin() || it == bounds.end()) return -1;
  return int(it - bounds.begin()) - 1;
}

// Median azimuth step between neighbouring points of one row (gaps over 2 deg are holes, not
// steps), or 0 if no row holds two points. Up to 16 rows spread over the image are enough.
double measured_step_deg(std::vector<std::vector<double>>& row_azimuths) {
  std::vector<double> gaps;
  const size_t stride = std::max<size_t>(1, row_azimuths.size() / 16);
  for (size_t r = 0; r < row_azimuths.size(); r += stride) {
    std::vector<double>& az = row_azimuths[r];
    std::sort(az.begin(), az.end());
    for (size_t k = 1; k < az.size(); ++k) {
      const double g = az[k] - az[k - 1];
      if (g > 1e-4 && g < 2.0) gaps.push_back(g);
    }
  }
  if (gaps.empty()) return 0.0;
  std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
  return gaps[gaps.size() / 2];
}

// Per row, the circular mean of its points' azimuths modulo the column step (in columns):
// columns are then centred on the firings, and a point's column is its azimuth rounded.
std::vector<float> row_phases(const std::vector<std::vector<double>>& row_azimuths, double step_deg) {
  std::vector<float> phase(row_azimuths.size(), 0.0f);
  for (size_t r = 0; r < row_azimuths.size(); ++r) {
    double s = 0.0, c = 0.0;
    for (double az : row_azimuths[r])
      s += std::sin(2.0 * M_PI * az / step_deg), c += std::cos(2.0 * M_PI * az / step_deg);
    if (s != 0.0 || c != 0.0) phase[r] = float(std::atan2(s, c) / (2.0 * M_PI));
  }
  return phase;
}

// Whether two points with beams (range, unit direction) are one object (the paper's beta test).
bool one_object(float r1, const Eigen::Vector3f& u1, float r2, const Eigen::Vector3f& u2, double tan_beta) {
  const double d1 = std::max(r1, r2), d2 = std::min(r1, r2);
  const double cos_a = std::clamp(double(u1.dot(u2)), -1.0, 1.0), sin_a = std::sqrt(1.0 - cos_a * cos_a);
  const double num = d2 * sin_a, den = d1 - d2 * cos_a;  // beta = atan2(num, den)
  return den <= 0.0 || num > tan_beta * den;
}

struct Pixels {
  std::vector<int> rep;  // per pixel: index of its nearest point, -1 if empty
  std::vector<int> pixel_of;
};

Pixels fill_pixels(const RangeImageGrid& g, const Beams& b) {
  Pixels p{std::vector<int>(size_t(g.rows()) * g.columns, -1), std::vector<int>(b.range.size(), -1)};
  for (size_t i = 0; i < b.range.size(); ++i) {
    if (b.range[i] <= 0.0f) continue;
    const int r = row_of(g.row_bounds_deg, elevation_deg(b.dir[i]));
    if (r < 0) continue;
    const long c = std::lround(azimuth_deg(b.dir[i]) / g.azimuth_step_deg - g.row_phase[size_t(r)]);
    const int px = r * g.columns + int(((c % g.columns) + g.columns) % g.columns);
    p.pixel_of[i] = px;
    int& rep = p.rep[size_t(px)];
    if (rep < 0 || b.range[i] < b.range[size_t(rep)]) rep = int(i);
  }
  return p;
}

// Breadth-first labelling of the pixels' N4 neighbourhoods, wrapping around in azimuth (the
// scan is a closed circle: an object on column 0 and the last column is one).
std::vector<uint32_t> label_pixels(const RangeImageGrid& g, const Pixels& p, const Beams& b, double tan_beta) {
  const int rows = g.rows(), cols = g.columns;
  std::vector<uint32_t> label(p.rep.size(), 0);
  std::vector<int> queue;
  uint32_t next = 0;
  for (size_t start = 0; start < p.rep.size(); ++start) {
    if (p.rep[start] < 0 || label[start]) continue;
    label[start] = ++next;
    queue.assign(1, int(start));
    for (size_t q = 0; q < queue.size(); ++q) {
      const int px = queue[q], r = px / cols, c = px % cols;
      const size_t i = size_t(p.rep[size_t(px)]);
      const int around[4] = {r > 0 ? px - cols : -1, r + 1 < rows ? px + cols : -1, r * cols + (c + cols - 1) % cols,
                             r * cols + (c + 1) % cols};
      for (const int nb : around) {
        if (nb < 0 || p.rep[size_t(nb)] < 0 || label[size_t(nb)]) continue;
        const size_t j = size_t(p.rep[size_t(nb)]);
        if (!one_object(b.range[i], b.dir[i], b.range[j], b.dir[j], tan_beta)) continue;
        label[size_t(nb)] = next;
        queue.push_back(nb);
      }
    }
  }
  return label;
}

}  // namespace

RangeImageGrid fit_range_image(const PointCloud& scan, const Eigen::Vector3f& sensor, const SegmenterConfig& config) {
  config.validate();
  RangeImageGrid g;
  g.sensor = sensor;
  Beams b = beams_of(scan, sensor);
  std::vector<Eigen::Vector3f> far;  // measure_input's ring points: beyond kRingMinRangeM
  for (size_t i = 0; i < scan.size(); ++i)
    if (b.range[i] >= InputMeasurements::kRingMinRangeM) far.push_back(b.dir[i]);
  if (far.size() < size_t(kMinFitPoints)) return g;
  g.to_image = image_frame(config.range_image_rows > 0 ? Eigen::Vector3f::UnitZ()
                                                       : rings_axis(spread_sample(far, kAxisSamples)));
  double lo = 90.0, hi = -90.0;
  std::vector<double> far_elevations;
  for (size_t i = 0; i < scan.size(); ++i) {
    if (b.range[i] <= 0.0f) continue;
    b.dir[i] = g.to_image * b.dir[i];
    const double e = elevation_deg(b.dir[i]);
    lo = std::min(lo, e), hi = std::max(hi, e);
    if (b.range[i] >= InputMeasurements::kRingMinRangeM) far_elevations.push_back(e);
  }
  far_elevations = spread_sample(far_elevations, kRingSamples);  // measure_rings sorts them
  const int uniform = config.range_image_rows;
  if (uniform > 0) {
    hi = std::max(hi, lo + 1e-3);
    for (int r = 0; r <= uniform; ++r) g.row_bounds_deg.push_back(float(lo + (hi - lo) * r / uniform));
    g.row_bounds_deg.back() = std::nextafter(float(hi), 90.0f);  // the highest point is in
  } else {
    g.row_bounds_deg = ring_bounds(far_elevations, lo, hi);
    g.rings = !g.row_bounds_deg.empty();
    if (!g.rings) return g;
  }
  std::vector<std::vector<double>> row_azimuths(size_t(g.rows()));
  for (size_t i = 0; i < scan.size(); ++i) {
    const int r = b.range[i] > 0.0f ? row_of(g.row_bounds_deg, elevation_deg(b.dir[i])) : -1;
    if (r >= 0) row_azimuths[size_t(r)].push_back(azimuth_deg(b.dir[i]));
  }
  double step = config.range_image_azimuth_step_deg;
  if (step == 0.0) step = g.rings ? measured_step_deg(row_azimuths) : (hi - lo) / uniform;
  g.columns = int(std::lround(360.0 / std::max(step, double(kMinStepDeg))));
  g.azimuth_step_deg = float(360.0 / g.columns);
  g.row_phase = g.rings ? row_phases(row_azimuths, g.azimuth_step_deg) : std::vector<float>(size_t(g.rows()), 0.0f);
  return g;
}

std::vector<uint32_t> range_image_components(const RangeImageGrid& grid, const PointCloud& cloud,
                                             const SegmenterConfig& config) {
  config.validate();
  if (!grid.valid()) throw std::invalid_argument("range_image_components: the grid is not valid (no rows)");
  Beams b = beams_of(cloud, grid.sensor);
  for (Eigen::Vector3f& d : b.dir) d = grid.to_image * d;
  const Pixels p = fill_pixels(grid, b);
  const double tan_beta = std::tan(double(config.range_image_beta_deg) * kDeg);
  const std::vector<uint32_t> pixel_label = label_pixels(grid, p, b, tan_beta);
  std::vector<uint32_t> component(cloud.size(), 0);
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (p.pixel_of[i] < 0) continue;
    // A point behind (or beside) its pixel's nearest one joins it only by the same beta test.
    const size_t rep = size_t(p.rep[size_t(p.pixel_of[i])]);
    if (rep == i || one_object(b.range[i], b.dir[i], b.range[rep], b.dir[rep], tan_beta))
      component[i] = pixel_label[size_t(p.pixel_of[i])];
  }
  return component;
}

Segments segments_of_components(const PointCloud& cloud, const std::vector<uint32_t>& components,
                                const SegmenterConfig& config, const std::vector<uint32_t>* labels) {
  config.validate();
  if (components.size() != cloud.size())
    throw std::invalid_argument("segments_of_components: components size differs from cloud size");
  if (labels && labels->size() != cloud.size())
    throw std::invalid_argument("segments_of_components: labels size differs from cloud size");
  // collect_clusters wants each group named by an item of it: the first point of each component.
  std::vector<uint32_t> order, root, first;
  for (size_t i = 0; i < cloud.size(); ++i) {
    const uint32_t c = components[i];
    if (c == 0 || !detail::is_finite(cloud[i])) continue;
    if (first.size() <= c) first.resize(size_t(c) + 1, UINT32_MAX);
    if (first[c] == UINT32_MAX) first[c] = uint32_t(order.size());
    root.push_back(first[c]);
    order.push_back(uint32_t(i));
  }
  return detail::build_segments(cloud, detail::collect_clusters(order, std::move(root), config), labels);
}

}  // namespace segmatch
