// Ground removal (paper III-A: "clustering adjacent voxels based on vertical means and
// variances", Douillard et al. 2011; IV-A: on KITTI "filtering the input scan by minimum
// height").
//
// kColumnVariance works on vertical columns:
//   1. per column: min, max, mean and standard deviation of z;
//   2. a column is flat if its vertical spread and deviation are small;
//   3. the lower envelope (lowest point within ~1.5 tiles) flags flat columns near the
//      bottom of the scene as ground seeds; a global threshold would fail on slopes;
//   4. ground grows from the seeds into adjacent flat columns with similar mean height
//      (the "clustering adjacent voxels" of Douillard et al.);
//   5. ground columns are removed whole; in the other columns (cars, trunks, walls on the
//      road) the points within a margin of the ground height of nearby ground columns go.
#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

#include "detail/seg_grid.h"
#include "segmatch/core/preprocess/preprocess.h"

namespace segmatch {
namespace {

using detail::FlatHashMap;
using detail::GridFrame;

void require_positive(float v, const char* field) {
  if (!(v > 0.0f) || !std::isfinite(v)) {
    throw std::invalid_argument(std::string("GroundConfig.") + field + " must be positive");
  }
}

// floor(v / cell) - base exactly as GridFrame::coord() computes it, but by a multiplication
// with 1 / cell (a division per coordinate was half the time of this stage): the product is
// off by a few ulps, which only matters within 1e-12 (relative) of a column boundary, and
// those rare values take the division.
struct ColumnCoord {
  const GridFrame& frame;
  double inv = 1.0 / frame.cell_m;
  int64_t operator()(float v, int axis) const {
    const double q = double(v) * inv;
    int64_t t = detail::fast_floor(q);
    const double frac = q - double(t), eps = 1e-12 * (std::abs(q) + 1.0);
    if (frac < eps || frac > 1.0 - eps) t = detail::fast_floor(double(v) / frame.cell_m);
    return t - frame.base[axis];
  }
};

// Packed key -> value with the answers of FlatHashMap for every key (even keys packed from
// out-of-range coordinates), but a dense table indexed by the key itself when the frame
// is small (a 120 m local cloud at 0.5 m packs into 16 bits): a lookup is then one load
// instead of a hash probe with a likely cache miss.
class KeyIndex {
 public:
  static constexpr uint32_t kMissing = FlatHashMap::kMissing;
  KeyIndex() = default;
  KeyIndex(int key_bits, size_t points) {
    const uint64_t dense_limit = std::max<uint64_t>(uint64_t{1} << 18, 2 * uint64_t{points});
    if (key_bits < 32 && (uint64_t{1} << key_bits) <= dense_limit) {
      dense_.assign(size_t{1} << key_bits, kMissing);
    } else {
      hash_.reserve(points / 8 + 16);
    }
  }
  // Inserted keys are packed from in-range coordinates, hence below 2^key_bits.
  uint32_t insert(uint64_t key, uint32_t value) {
    if (dense_.empty()) return hash_.insert(key, value);
    uint32_t& v = dense_[key];
    if (v == kMissing) v = value;
    return v;
  }
  uint32_t find(uint64_t key) const {
    if (dense_.empty()) return hash_.find(key);
    return key < dense_.size() ? dense_[key] : kMissing;
  }

 private:
  std::vector<uint32_t> dense_;
  FlatHashMap hash_;
};

struct ColumnStats {
  float zmin = 0.f, zmax = 0.f, mean = 0.f, stddev = 0.f;
};

// The occupied columns, numbered in order of first appearance (no sort: every step below is
// independent of the numbering), with a lookup by integer coordinates.
struct Columns {
  GridFrame frame;
  KeyIndex index;             // packed (x, y) -> column
  std::vector<int64_t> x, y;  // coordinates per column
  std::vector<uint32_t> of;   // column of each point (kMissing if not finite)
  std::vector<ColumnStats> stats;
  size_t size() const { return x.size(); }
  uint32_t at(int64_t cx, int64_t cy) const {
    return frame.inside(cx, cy, 0) ? index.find(frame.pack(cx, cy, 0)) : FlatHashMap::kMissing;
  }
};

// bounds[k] = the least float that ColumnCoord maps to k or above, along one axis, so that
// column k holds exactly [bounds[k], bounds[k + 1]) (ColumnCoord is monotone): two float
// compares per axis then tell whether a point stays in the column of the previous one.
// The ends are -FLT_MAX and +inf, so the test also rejects infinities and NaN. Empty (no
// test) if the axis has so many columns that the table would cost more than it saves.
std::vector<float> column_bounds(const ColumnCoord& coord, int axis, size_t points) {
  const int64_t extent = coord.frame.extent[axis];
  if (extent > int64_t(1024 + points / 16)) return {};
  std::vector<float> bounds(size_t(extent) + 1);
  bounds[0] = -std::numeric_limits<float>::max();
  bounds[extent] = std::numeric_limits<float>::infinity();
  const float down = -std::numeric_limits<float>::infinity(), up = -down;
  for (int64_t k = 1; k < extent; ++k) {
    float f = float(double(coord.frame.base[axis] + k) * coord.frame.cell_m);
    while (coord(f, axis) >= k) f = std::nextafter(f, down);
    while (coord(f, axis) < k) f = std::nextafter(f, up);
    bounds[k] = f;
  }
  return bounds;
}

struct ColumnSums {
  double sum = 0, sum2 = 0;
  float lo = 0, hi = 0;
  uint32_t n = 0;
  void add(float z) {
    sum += z;
    sum2 += double(z) * z;
    lo = std::min(lo, z);
    hi = std::max(hi, z);
    ++n;
  }
};

// Float box [x_lo, x_hi) x [y_lo, y_hi) of one column; the default is empty.
struct ColumnBox {
  float x_lo = 1.f, x_hi = 0.f, y_lo = 1.f, y_hi = 0.f;
  bool holds(const Point& p) const { return p.x >= x_lo && p.x < x_hi && p.y >= y_lo && p.y < y_hi; }
};

// Adds point i (in column c) and the run of points after it that lie in the box of c;
// returns the index after the run. A local copy keeps the sums in registers.
size_t add_run(const PointCloud& cloud, size_t i, const ColumnBox& box, uint32_t c, ColumnSums* column, uint32_t* of) {
  ColumnSums s = *column;
  s.add(cloud[i].z);
  of[i] = c;
  for (++i; i < cloud.size() && box.holds(cloud[i]); ++i) {
    if (!std::isfinite(cloud[i].z)) continue;
    s.add(cloud[i].z);
    of[i] = c;
  }
  *column = s;
  return i;
}

// Step 1 in one pass over the points; the sums run in input order per column. Voxelized
// input comes in voxel order, so runs of points share a column: those skip the coordinates
// and the lookup.
Columns build_columns(const PointCloud& cloud, double column_m) {
  Columns cols;
  cols.frame = GridFrame::fit(cloud, column_m, true, "GroundConfig.column_size_m");
  cols.index = KeyIndex(cols.frame.total_bits, cloud.size());
  cols.of.assign(cloud.size(), FlatHashMap::kMissing);
  const ColumnCoord coord{cols.frame};
  const std::vector<float> bx = column_bounds(coord, 0, cloud.size());
  const std::vector<float> by = column_bounds(coord, 1, cloud.size());
  const bool bounded = !bx.empty() && !by.empty();
  std::vector<ColumnSums> sums;
  uint64_t last_key = ~uint64_t{0};
  uint32_t column = 0;
  for (size_t i = 0; i < cloud.size();) {
    const Point& p = cloud[i];
    if (!detail::is_finite(p)) {
      ++i;
      continue;
    }
    const int64_t cx = coord(p.x, 0), cy = coord(p.y, 1);
    const uint64_t key = cols.frame.pack(cx, cy, 0);
    if (key != last_key) {
      column = cols.index.insert(key, static_cast<uint32_t>(sums.size()));
      last_key = key;
      if (column == sums.size()) {
        sums.push_back({0, 0, p.z, p.z, 0});
        cols.x.push_back(cx);
        cols.y.push_back(cy);
      }
    }
    ColumnBox box;
    if (bounded) box = {bx[cx], bx[cx + 1], by[cy], by[cy + 1]};
    i = add_run(cloud, i, box, column, &sums[column], cols.of.data());
  }
  cols.stats.resize(sums.size());
  for (size_t c = 0; c < sums.size(); ++c) {
    const double n = sums[c].n, mean = sums[c].sum / n;
    const double var = std::max(0.0, sums[c].sum2 / n - mean * mean);
    cols.stats[c] = {sums[c].lo, sums[c].hi, float(mean), float(std::sqrt(var))};
  }
  return cols;
}

// Lowest point among the 3 x 3 tiles (tile = tile_cols x tile_cols columns) around each
// column: the local bottom of the scene.
std::vector<float> lower_envelope(const Columns& cols, int64_t tile_cols) {
  KeyIndex tile_index(cols.frame.total_bits, cols.of.size());
  std::vector<float> tile_min;
  std::vector<uint32_t> column_tile(cols.size());
  const auto tile_key = [&](int64_t tx, int64_t ty) { return cols.frame.pack(tx, ty, 0); };
  for (uint32_t c = 0; c < cols.size(); ++c) {
    const uint32_t t = tile_index.insert(tile_key(cols.x[c] / tile_cols, cols.y[c] / tile_cols),
                                         static_cast<uint32_t>(tile_min.size()));
    if (t == tile_min.size()) tile_min.push_back(cols.stats[c].zmin);
    tile_min[t] = std::min(tile_min[t], cols.stats[c].zmin);
    column_tile[c] = t;
  }
  std::vector<float> envelope(cols.size());
  for (uint32_t c = 0; c < cols.size(); ++c) {
    const int64_t tx = cols.x[c] / tile_cols, ty = cols.y[c] / tile_cols;
    float lo = tile_min[column_tile[c]];
    for (int64_t dx = -1; dx <= 1; ++dx) {
      for (int64_t dy = -1; dy <= 1; ++dy) {
        if (tx + dx < 0 || ty + dy < 0) continue;
        const uint32_t t = tile_index.find(tile_key(tx + dx, ty + dy));
        if (t != FlatHashMap::kMissing) lo = std::min(lo, tile_min[t]);
      }
    }
    envelope[c] = lo;
  }
  return envelope;
}

// Steps 2-4: flat seed columns near the envelope, grown over 8-connected flat columns.
std::vector<char> ground_columns(const Columns& cols, const std::vector<float>& envelope, const GroundConfig& cfg) {
  const size_t n = cols.size();
  const std::vector<ColumnStats>& stats = cols.stats;
  std::vector<char> flat(n), ground(n, 0);
  std::vector<uint32_t> stack;
  for (uint32_t c = 0; c < n; ++c) {
    flat[c] = stats[c].zmax - stats[c].zmin <= cfg.max_column_spread_m && stats[c].stddev <= cfg.max_column_stddev_m;
    if (flat[c] && stats[c].mean - envelope[c] <= cfg.seed_tolerance_m) {
      ground[c] = 1;
      stack.push_back(c);
    }
  }
  // The grown set is everything reachable from a seed, whatever the visiting order.
  while (!stack.empty()) {
    const uint32_t c = stack.back();
    stack.pop_back();
    for (int64_t dx = -1; dx <= 1; ++dx) {
      for (int64_t dy = -1; dy <= 1; ++dy) {
        const uint32_t nb = cols.at(cols.x[c] + dx, cols.y[c] + dy);
        if (nb == FlatHashMap::kMissing || ground[nb] || !flat[nb]) continue;
        if (std::abs(stats[nb].mean - stats[c].mean) > cfg.max_step_m) continue;
        ground[nb] = 1;
        stack.push_back(nb);
      }
    }
  }
  return ground;
}

// Ground height under a non-ground column: mean of the ground columns in the nearest ring
// that has any (up to max_search_rings), else the lower envelope.
float ground_height(const Columns& cols, uint32_t c, const std::vector<char>& ground, float envelope, int max_rings) {
  for (int64_t r = 1; r <= max_rings; ++r) {
    double sum = 0;
    int count = 0;
    for (int64_t dx = -r; dx <= r; ++dx) {
      // Ring r only: the full edge rows, two cells of the others.
      const int64_t step = (dx == -r || dx == r) ? 1 : 2 * r;
      for (int64_t dy = -r; dy <= r; dy += step) {
        const uint32_t nb = cols.at(cols.x[c] + dx, cols.y[c] + dy);
        if (nb == FlatHashMap::kMissing || !ground[nb]) continue;
        sum += cols.stats[nb].mean;
        ++count;
      }
    }
    if (count > 0) return float(sum / count);
  }
  return envelope;
}

std::vector<bool> column_variance_mask(const PointCloud& cloud, const GroundConfig& cfg) {
  std::vector<bool> mask(cloud.size(), true);  // non-finite points count as ground
  if (cloud.empty()) return mask;
  const Columns cols = build_columns(cloud, cfg.column_size_m);
  const int64_t tile_cols = std::max<int64_t>(1, std::llround(cfg.envelope_tile_m / cfg.column_size_m));
  const std::vector<float> envelope = lower_envelope(cols, tile_cols);
  const std::vector<char> ground = ground_columns(cols, envelope, cfg);
  // Per column c: points below limit[c + 1] are ground (+inf: the whole column). Entry 0
  // is read for the non-finite points (column kMissing + 1 wraps to 0), so that the loop
  // below has no branch; its comparison is overridden.
  std::vector<float> limit(cols.size() + 1, std::numeric_limits<float>::infinity());
  for (uint32_t c = 0; c < cols.size(); ++c) {
    if (ground[c]) continue;
    limit[c + 1] = ground_height(cols, c, ground, envelope[c], cfg.max_search_rings) + cfg.ground_margin_m;
  }
  for (size_t i = 0; i < cloud.size(); ++i) {
    const uint32_t c = cols.of[i];
    mask[i] = (cloud[i].z < limit[uint32_t(c + 1)]) | (c == FlatHashMap::kMissing);
  }
  return mask;
}

}  // namespace

void GroundConfig::validate() const {
  if (!std::isfinite(height_above_ground_m)) {
    throw std::invalid_argument("GroundConfig.height_above_ground_m must be finite");
  }
  if (!std::isfinite(sensor_height_m)) {
    throw std::invalid_argument("GroundConfig.sensor_height_m must be finite");
  }
  require_positive(column_size_m, "column_size_m");
  require_positive(max_column_spread_m, "max_column_spread_m");
  require_positive(max_column_stddev_m, "max_column_stddev_m");
  require_positive(envelope_tile_m, "envelope_tile_m");
  require_positive(seed_tolerance_m, "seed_tolerance_m");
  require_positive(max_step_m, "max_step_m");
  if (!(ground_margin_m >= 0.0f) || !std::isfinite(ground_margin_m)) {
    throw std::invalid_argument("GroundConfig.ground_margin_m must be >= 0");
  }
  if (max_search_rings < 1) {
    throw std::invalid_argument("GroundConfig.max_search_rings must be >= 1");
  }
}

std::vector<bool> ground_mask(const PointCloud& cloud, const GroundConfig& config,
                              const Eigen::Vector3f& sensor_position) {
  config.validate();
  switch (config.method) {
    case GroundRemoval::kNone: return std::vector<bool>(cloud.size(), false);
    case GroundRemoval::kHeightThreshold: {
      const float limit = sensor_position.z() - config.sensor_height_m + config.height_above_ground_m;
      std::vector<bool> mask(cloud.size());
      for (size_t i = 0; i < cloud.size(); ++i) mask[i] = !(cloud[i].z >= limit);
      return mask;
    }
    case GroundRemoval::kColumnVariance: return column_variance_mask(cloud, config);
  }
  throw std::invalid_argument("GroundConfig.method is not a known GroundRemoval");
}

PointCloud remove_ground(const PointCloud& cloud, const GroundConfig& config, const Eigen::Vector3f& sensor_position,
                         const std::vector<uint32_t>* labels, std::vector<uint32_t>* labels_out) {
  if (labels && labels->size() != cloud.size()) {
    throw std::invalid_argument("remove_ground: labels size differs from cloud size");
  }
  const std::vector<bool> mask = ground_mask(cloud, config, sensor_position);
  PointCloud out;
  out.reserve(cloud.size());
  if (labels_out) labels_out->clear();
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (mask[i]) continue;
    out.push_back(cloud[i]);
    if (labels && labels_out) labels_out->push_back((*labels)[i]);
  }
  return out;
}

}  // namespace segmatch
