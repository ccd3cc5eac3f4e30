#include "segmatch/core/localization/correlative_search.h"

#include "detail/config_checks.h"
#include "detail/seg_grid.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch {

void CorrelativeSearchConfig::validate() const {
  auto positive = [](float v, const char* name) { detail::require_positive(v, "CorrelativeSearchConfig", name); };
  positive(max_radius_m, "max_radius_m");
  positive(resolution_m, "resolution_m");
  positive(angle_step_deg, "angle_step_deg");
  detail::require_non_negative(min_separation_m, "CorrelativeSearchConfig", "min_separation_m");
  if (max_query_points < 10) throw std::invalid_argument("CorrelativeSearchConfig.max_query_points must be >= 10");
  detail::require_fraction(min_fitness, "CorrelativeSearchConfig", "min_fitness");
  if (candidates < 1) throw std::invalid_argument("CorrelativeSearchConfig.candidates must be >= 1");
}

namespace {

// The map's points top-down on a square grid centred on the prior's sensor, each occupied cell
// spread to its neighbours with a Gaussian of one cell (a point a cell off still scores 0.61).
class LikelihoodGrid {
 public:
  LikelihoodGrid(const PointCloud& map, const Eigen::Vector2d& centre, double half_m, double cell_m)
      : cell_m_(cell_m), size_(static_cast<int>(std::ceil(2.0 * half_m / cell_m)) + 1) {
    origin_ = centre - Eigen::Vector2d::Constant(half_m);
    values_.assign(static_cast<size_t>(size_) * size_, 0.0f);
    std::vector<uint8_t> occupied(values_.size(), 0);
    for (const Point& p : map) {
      const int64_t x = detail::fast_floor((p.x - origin_.x()) / cell_m),
                    y = detail::fast_floor((p.y - origin_.y()) / cell_m);
      if (x >= 0 && y >= 0 && x < size_ && y < size_) occupied[static_cast<size_t>(x) * size_ + y] = 1;
    }
    constexpr int kSpread = 2;
    float kernel[2 * kSpread + 1][2 * kSpread + 1];
    for (int dx = -kSpread; dx <= kSpread; ++dx)
      for (int dy = -kSpread; dy <= kSpread; ++dy)
        kernel[dx + kSpread][dy + kSpread] = static_cast<float>(std::exp(-0.5 * (dx * dx + dy * dy)));
    for (int x = 0; x < size_; ++x)
      for (int y = 0; y < size_; ++y) {
        if (!occupied[static_cast<size_t>(x) * size_ + y]) continue;
        for (int dx = -kSpread; dx <= kSpread; ++dx)
          for (int dy = -kSpread; dy <= kSpread; ++dy) {
            const int u = x + dx, v = y + dy;
            if (u < 0 || v < 0 || u >= size_ || v >= size_) continue;
            float& value = values_[static_cast<size_t>(u) * size_ + v];
            value = std::max(value, kernel[dx + kSpread][dy + kSpread]);
          }
      }
  }
  // The cell of a map-frame position (may be outside the grid).
  Eigen::Vector2i cell_of(const Eigen::Vector2d& p) const {
    return {static_cast<int>(detail::fast_floor((p.x() - origin_.x()) / cell_m_)),
            static_cast<int>(detail::fast_floor((p.y() - origin_.y()) / cell_m_))};
  }
  float at(int x, int y) const {
    return (x < 0 || y < 0 || x >= size_ || y >= size_) ? 0.0f : values_[static_cast<size_t>(x) * size_ + y];
  }

 private:
  double cell_m_;
  int size_;
  Eigen::Vector2d origin_;
  std::vector<float> values_;
};

// The query's points within reach of the sensor, relative to it (query frame), one per occupied
// cell (dense near-range surfaces would otherwise outvote the scene), then every k-th.
std::vector<Eigen::Vector3d> query_offsets(const PointCloud& query, const Eigen::Vector3d& sensor, double reach_m,
                                           const CorrelativeSearchConfig& c) {
  detail::FlatHashMap seen(query.size() / 4 + 16);
  std::vector<Eigen::Vector3d> out;
  for (const Point& p : query) {
    const Eigen::Vector3d d = p.xyz().cast<double>() - sensor;
    if (d.head<2>().norm() > reach_m) continue;
    const uint64_t key =
        detail::pack_xy(detail::fast_floor(d.x() / c.resolution_m), detail::fast_floor(d.y() / c.resolution_m));
    if (seen.insert(key, static_cast<uint32_t>(out.size())) == out.size()) out.push_back(d);
  }
  const size_t stride = (out.size() + c.max_query_points - 1) / static_cast<size_t>(c.max_query_points);
  if (stride <= 1) return out;
  std::vector<Eigen::Vector3d> thinned;
  for (size_t i = 0; i < out.size(); i += stride) thinned.push_back(out[i]);
  return thinned;
}

struct Peak {
  double score;
  int dx, dy, heading;
};

}  // namespace

std::vector<SearchCandidate> correlative_search(const PointCloud& query_points, const PointCloud& map_points,
                                                const Pose3d& T_map_query_prior, const Eigen::Vector3d& sensor_query,
                                                double radius_m, double heading_tolerance_deg, double window_m,
                                                const CorrelativeSearchConfig& c) {
  c.validate();
  const std::vector<Eigen::Vector3d> offsets = query_offsets(query_points, sensor_query, window_m, c);
  if (offsets.empty() || map_points.empty()) return {};
  const Eigen::Vector3d sensor_map = T_map_query_prior * sensor_query;
  const double cell = c.resolution_m;
  const LikelihoodGrid grid(map_points, sensor_map.head<2>(), radius_m + window_m + 2.0 * cell, cell);
  const int steps = static_cast<int>(std::floor(radius_m / cell));
  const int turns = static_cast<int>(std::floor(heading_tolerance_deg / c.angle_step_deg));
  const Eigen::Vector2i centre = grid.cell_of(sensor_map.head<2>());
  std::vector<Peak> best;  // per translation, its best heading
  best.assign(static_cast<size_t>(2 * steps + 1) * (2 * steps + 1), Peak{-1.0, 0, 0, 0});
  std::vector<Eigen::Vector2i> cells(offsets.size());
  for (int h = -turns; h <= turns; ++h) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(h * c.angle_step_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
        T_map_query_prior.linear();
    for (size_t i = 0; i < offsets.size(); ++i)
      cells[i] = grid.cell_of(sensor_map.head<2>() + (R * offsets[i]).head<2>()) - centre;
    for (int dx = -steps; dx <= steps; ++dx)
      for (int dy = -steps; dy <= steps; ++dy) {
        if (dx * dx + dy * dy > steps * steps) continue;
        double sum = 0.0;
        for (const Eigen::Vector2i& q : cells) sum += grid.at(centre.x() + dx + q.x(), centre.y() + dy + q.y());
        Peak& p = best[static_cast<size_t>(dx + steps) * (2 * steps + 1) + (dy + steps)];
        if (sum > p.score) p = Peak{sum, dx, dy, h};
      }
  }
  std::sort(best.begin(), best.end(), [](const Peak& a, const Peak& b) { return a.score > b.score; });
  std::vector<SearchCandidate> out;
  const double min_sep_cells = c.min_separation_m / cell;
  for (const Peak& p : best) {
    if (p.score <= 0.0 || out.size() >= static_cast<size_t>(c.candidates)) break;
    bool distinct = true;
    for (const SearchCandidate& o : out) {
      const Eigen::Vector2d d =
          (o.T_map_query * sensor_query - sensor_map).head<2>() / cell - Eigen::Vector2d(p.dx, p.dy);
      distinct = distinct && d.norm() >= min_sep_cells;
    }
    if (!distinct) continue;
    // The candidate turns the prior about the vertical through its sensor, then moves it.
    Pose3d T = Pose3d::Identity();
    T.linear() =
        Eigen::AngleAxisd(p.heading * c.angle_step_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = sensor_map - T.linear() * sensor_map + Eigen::Vector3d(p.dx * cell, p.dy * cell, 0.0);
    out.push_back({T * T_map_query_prior, p.score / static_cast<double>(offsets.size())});
  }
  return out;
}

}  // namespace segmatch
