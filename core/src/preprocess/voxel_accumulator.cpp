// Incremental voxel grid of a local cloud (see voxel_accumulator.h).
#include "segmatch/core/preprocess/voxel_accumulator.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "detail/seg_grid.h"
#include "detail/voxel_table.h"

namespace segmatch {
namespace {

using namespace voxel_table;

constexpr double kMaxRangeM = 20000.0;  // farther from the sensor is refused (key wrap safety)
constexpr double kTileMarginM = 1e-3;   // tiles this close to the boundary are recomputed

// Voxel of a point, floor(v / leaf) per axis exactly as voxel_filter (GridFrame::coord), and
// the position inside it in fixed point. False if the point is not finite.
struct Voxelized {
  int64_t v[3];
  int64_t f[3];
};
inline bool voxelize(const Point& p, double leaf, Voxelized* out) {
  if (!detail::is_finite(p)) return false;
  const float c[3] = {p.x, p.y, p.z};
  for (int a = 0; a < 3; ++a) {
    const double q = double(c[a]) / leaf;
    const int64_t t = detail::fast_floor(q);
    out->v[a] = t;
    const double fr = (q - double(t)) * kFracScale;
    out->f[a] = std::min<int64_t>(std::max<int64_t>(static_cast<int64_t>(fr), 0), int64_t{0xFFFFFFFF});
  }
  return true;
}

struct Tile {
  int64_t x, y;    // tile coordinates (voxel column >> kTileShift)
  uint32_t begin;  // first point of the tile in the scan; the next tile's begin ends it
};

struct Scan {
  PointCloud points;             // world frame, grouped by tile
  std::vector<uint32_t> labels;  // empty if none were given
  std::vector<Tile> tiles;       // plus a sentinel holding points.size()
  float min_xy[2] = {0.f, 0.f};
  float max_xy[2] = {0.f, 0.f};
  double added_at_m = 0.0;  // odometer when it was added (LocalCloud's)
};

// Adds (sign +1) or subtracts (-1) points [begin, end) into the table, computing the keys of
// a batch and prefetching their slots before touching any.
void sum_points(const PointCloud& points, const std::vector<uint32_t>& labels, size_t begin, size_t end, double leaf,
                int sign, VoxelTable* table) {
  constexpr size_t kBatch = 16;
  uint32_t keys[kBatch];
  int64_t frac[kBatch][3];
  uint32_t idx[kBatch];
  for (size_t start = begin; start < end; start += kBatch) {
    const size_t stop = std::min(end, start + kBatch);
    size_t m = 0;
    for (size_t i = start; i < stop; ++i) {
      Voxelized v;
      if (!voxelize(points[i], leaf, &v)) continue;
      keys[m] = local_key(v.v);
      std::copy(v.f, v.f + 3, frac[m]);
      idx[m] = static_cast<uint32_t>(i);
      table->prefetch(keys[m++]);
    }
    for (size_t k = 0; k < m; ++k)
      table->add(keys[k], frac[k], points[idx[k]].intensity, labels.empty() ? 0u : labels[idx[k]], sign);
  }
}

// Tiles against the cylinder: 0 wholly outside, 1 wholly inside (every point passes the point
// test), 2 crossed by the boundary. The margin covers the rounding of floor(v / leaf). Worked
// out once per crop for the tiles of the cylinder's bounding box, then looked up (a crop
// classifies every tile of every held scan); computed on the fly for a cylinder of more than
// 4 M tiles.
class TileClasses {
 public:
  TileClasses(double cx, double cy, double radius, double leaf)
      : cx_(cx),
        cy_(cy),
        tile_m_(leaf * double(int64_t{1} << kTileShift)),
        inner_(radius - kTileMarginM),
        outer_(radius + kTileMarginM) {
    x0_ = static_cast<int64_t>(std::floor((cx - radius) / tile_m_)) - 1;
    y0_ = static_cast<int64_t>(std::floor((cy - radius) / tile_m_)) - 1;
    nx_ = static_cast<int64_t>(std::floor((cx + radius) / tile_m_)) + 2 - x0_;
    ny_ = static_cast<int64_t>(std::floor((cy + radius) / tile_m_)) + 2 - y0_;
    if (double(nx_) * double(ny_) > double(1 << 22)) return;
    cls_.resize(static_cast<size_t>(nx_ * ny_));
    for (int64_t i = 0; i < nx_; ++i)
      for (int64_t j = 0; j < ny_; ++j) cls_[static_cast<size_t>(i * ny_ + j)] = compute(x0_ + i, y0_ + j);
  }
  int at(int64_t x, int64_t y) const {
    const int64_t i = x - x0_, j = y - y0_;
    if (i < 0 || j < 0 || i >= nx_ || j >= ny_) return 0;
    return cls_.empty() ? compute(x, y) : cls_[static_cast<size_t>(i * ny_ + j)];
  }

 private:
  uint8_t compute(int64_t x, int64_t y) const {
    const double xa = double(x) * tile_m_, xb = double(x + 1) * tile_m_;
    const double ya = double(y) * tile_m_, yb = double(y + 1) * tile_m_;
    const double nx = std::clamp(cx_, xa, xb) - cx_, ny = std::clamp(cy_, ya, yb) - cy_;
    if (nx * nx + ny * ny > outer_ * outer_) return 0;
    const double fx = std::max(std::abs(xa - cx_), std::abs(xb - cx_));
    const double fy = std::max(std::abs(ya - cy_), std::abs(yb - cy_));
    return (inner_ > 0 && fx * fx + fy * fy <= inner_ * inner_) ? 1 : 2;
  }

  double cx_, cy_, tile_m_, inner_, outer_;
  int64_t x0_ = 0, y0_ = 0, nx_ = 0, ny_ = 0;
  std::vector<uint8_t> cls_;
};

}  // namespace

// The voxels are kept per tile (a small table each), so that a crop visits only the tiles near
// the cylinder, not every voxel of the ~180 m of route whose scans still reach it, and a scan's
// points (grouped by tile) are summed into a table that stays in cache.
struct VoxelAccumulator::Impl {
  LocalCloudConfig local;
  VoxelGridConfig voxel;
  double leaf = 0.1;
  std::deque<Scan> scans;
  std::unordered_map<uint64_t, VoxelTable> tiles;
  bool has_last = false;
  Eigen::Vector3d last_position = Eigen::Vector3d::Zero();
  double odometer_m = 0.0;  // as LocalCloud's
  // Crop buffers, reused.
  PointCloud ring;
  std::vector<uint32_t> ring_labels;
  std::vector<KeptTile> kept;
  EmitScratch scratch;

  // Adds (+1) or subtracts (-1) a scan's points, tile by tile.
  void sum_scan(const Scan& s, int sign) {
    for (size_t t = 0; t + 1 < s.tiles.size(); ++t) {
      const uint64_t key = detail::pack_xy(s.tiles[t].x, s.tiles[t].y);
      const uint32_t b = s.tiles[t].begin, e = s.tiles[t + 1].begin;
      VoxelTable* table;
      if (sign > 0) {
        table = &tiles[key];
      } else {
        const auto it = tiles.find(key);
        if (it == tiles.end()) continue;  // cannot happen: the scan was added
        table = &it->second;
      }
      sum_points(s.points, s.labels, b, e, leaf, sign, table);
      if (sign < 0 && table->live() == 0) {
        tiles.erase(key);
      } else if (sign < 0) {
        table->compact();
      }
    }
  }
};

VoxelAccumulator::VoxelAccumulator(const LocalCloudConfig& local, const VoxelGridConfig& voxel)
    : impl_(std::make_unique<Impl>()) {
  local.validate();
  voxel.validate();
  impl_->local = local;
  impl_->voxel = voxel;
  impl_->leaf = double(voxel.leaf_m);  // as voxel_filter: the float leaf, in double
}
VoxelAccumulator::~VoxelAccumulator() = default;
VoxelAccumulator::VoxelAccumulator(VoxelAccumulator&&) noexcept = default;
VoxelAccumulator& VoxelAccumulator::operator=(VoxelAccumulator&&) noexcept = default;

bool VoxelAccumulator::add_scan(const PointCloud& scan_sensor, const Pose3d& T_world_sensor,
                                const std::vector<uint32_t>* labels) {
  Impl& m = *impl_;
  if (labels && labels->size() != scan_sensor.size()) {
    throw std::invalid_argument("VoxelAccumulator::add_scan: labels size differs from scan size");
  }
  const Eigen::Vector3d position = T_world_sensor.translation();
  if (m.has_last && (position - m.last_position).norm() < m.local.min_travel_between_scans_m) return false;

  // World-frame points exactly as LocalCloud::add_scan computes them.
  const std::vector<uint32_t> keep = detail::subsample_indices(scan_sensor, m.local.subsample_leaf_m);
  PointCloud world;
  world.reserve(keep.size());
  std::vector<uint32_t> world_labels;
  if (labels) world_labels.reserve(keep.size());
  const Eigen::Matrix3d R = T_world_sensor.linear();
  Scan scan;
  detail::reset_xy_bounds(scan.min_xy, scan.max_xy);
  for (uint32_t i : keep) {
    const Point q = detail::world_point(scan_sensor[i], R, position);
    if (!detail::is_finite(q)) continue;  // LocalCloud keeps these, but voxel_filter ignores them
    if (std::abs(q.x - position.x()) > kMaxRangeM || std::abs(q.y - position.y()) > kMaxRangeM ||
        std::abs(q.z - position.z()) > kMaxRangeM) {
      throw std::invalid_argument("VoxelAccumulator::add_scan: a point lies more than 20 km from the sensor");
    }
    world.push_back(q);
    if (labels) world_labels.push_back((*labels)[i]);
    detail::grow_xy_bounds(q, scan.min_xy, scan.max_xy);
  }
  if (m.has_last) m.odometer_m += (position - m.last_position).norm();
  m.has_last = true;
  m.last_position = position;
  scan.added_at_m = m.odometer_m;

  // Group the points by tile (stable radix sort on tile keys relative to the scan's first tile).
  const size_t n = world.size();
  std::vector<int64_t> tx(n), ty(n);
  int64_t lo[2] = {std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::max()};
  int64_t hi[2] = {std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::min()};
  for (size_t i = 0; i < n; ++i) {
    Voxelized v{};
    voxelize(world[i], m.leaf, &v);  // finite: checked above
    tx[i] = v.v[0] >> kTileShift;    // arithmetic shift: floor division
    ty[i] = v.v[1] >> kTileShift;
    lo[0] = std::min(lo[0], tx[i]), hi[0] = std::max(hi[0], tx[i]);
    lo[1] = std::min(lo[1], ty[i]), hi[1] = std::max(hi[1], ty[i]);
  }
  if (n > 0) {
    int ybits = 0;
    while ((int64_t{1} << ybits) <= hi[1] - lo[1]) ++ybits;
    int xbits = 0;
    while ((int64_t{1} << xbits) <= hi[0] - lo[0]) ++xbits;
    std::vector<uint64_t> keys(n);
    std::vector<uint32_t> order(n);
    for (size_t i = 0; i < n; ++i) {
      keys[i] = static_cast<uint64_t>(tx[i] - lo[0]) << ybits | static_cast<uint64_t>(ty[i] - lo[1]);
      order[i] = static_cast<uint32_t>(i);
    }
    detail::radix_sort(keys, order, std::max(xbits + ybits, 1));
    scan.points.resize(n);
    if (labels) scan.labels.resize(n);
    for (size_t k = 0; k < n; ++k) {
      scan.points[k] = world[order[k]];
      if (labels) scan.labels[k] = world_labels[order[k]];
      if (k == 0 || keys[k] != keys[k - 1])
        scan.tiles.push_back({tx[order[k]], ty[order[k]], static_cast<uint32_t>(k)});
    }
  }
  scan.tiles.push_back({0, 0, static_cast<uint32_t>(n)});
  m.sum_scan(scan, +1);
  m.scans.push_back(std::move(scan));
  return true;
}

PointCloud VoxelAccumulator::crop(const Pose3d& T_world_sensor, std::vector<uint32_t>* labels_out) {
  Impl& m = *impl_;
  const double cx = T_world_sensor.translation().x();
  const double cy = T_world_sensor.translation().y();
  const double radius = m.local.radius_m;
  const double r2 = radius * radius;
  const double leaf = m.leaf;
  if (labels_out) labels_out->clear();
  evict(T_world_sensor);
  if (m.scans.empty()) return {};
  const TileClasses classes(cx, cy, radius, leaf);

  // The boundary tiles' voxels, from the raw points inside the cylinder, one table per tile.
  std::unordered_map<uint64_t, VoxelTable> boundary;
  PointCloud& ring = m.ring;
  std::vector<uint32_t>& ring_labels = m.ring_labels;
  for (const Scan& s : m.scans) {
    for (size_t t = 0; t + 1 < s.tiles.size(); ++t) {
      if (classes.at(s.tiles[t].x, s.tiles[t].y) != 2) continue;
      ring.clear();
      ring_labels.clear();
      for (uint32_t i = s.tiles[t].begin; i < s.tiles[t + 1].begin; ++i) {
        const double dx = s.points[i].x - cx, dy = s.points[i].y - cy;
        if (dx * dx + dy * dy > r2) continue;  // LocalCloud::crop's test
        ring.push_back(s.points[i]);
        if (labels_out) ring_labels.push_back(s.labels.empty() ? 0u : s.labels[i]);
      }
      if (!ring.empty())
        sum_points(ring, ring_labels, 0, ring.size(), leaf, +1, &boundary[detail::pack_xy(s.tiles[t].x, s.tiles[t].y)]);
    }
  }

  // The kept tiles: wholly inside ones from their tables, boundary ones recomputed.
  std::vector<KeptTile>& kept = m.kept;
  kept.clear();
  for (const auto& [key, table] : m.tiles) {
    const int64_t x = detail::unpack_x(key), y = detail::unpack_y(key);
    if (classes.at(x, y) == 1) kept.push_back({x, y, &table});
  }
  for (const auto& [key, table] : boundary) kept.push_back({detail::unpack_x(key), detail::unpack_y(key), &table});
  const int64_t centre_z = static_cast<int64_t>(std::floor(T_world_sensor.translation().z() / leaf));
  return emit_in_key_order(kept, centre_z, leaf, static_cast<uint32_t>(m.voxel.min_points_per_voxel), labels_out,
                           &m.scratch);
}

void VoxelAccumulator::evict(const Pose3d& T_world_sensor) {
  Impl& m = *impl_;
  const double cx = T_world_sensor.translation().x(), cy = T_world_sensor.translation().y();
  // As LocalCloud::crop.
  const auto outside = [&](const Scan& s) {
    return detail::scan_leaves(s.min_xy, s.max_xy, s.points.empty(), s.added_at_m, m.odometer_m, cx, cy,
                               m.local.radius_m, m.local.max_scan_age_m);
  };
  for (const Scan& s : m.scans)
    if (outside(s)) m.sum_scan(s, -1);
  m.scans.erase(std::remove_if(m.scans.begin(), m.scans.end(), outside), m.scans.end());
}

size_t VoxelAccumulator::scan_count() const { return impl_->scans.size(); }

size_t VoxelAccumulator::point_count() const {
  size_t n = 0;
  for (const Scan& s : impl_->scans) n += s.points.size();
  return n;
}

size_t VoxelAccumulator::voxel_count() const {
  size_t n = 0;
  for (const auto& tile : impl_->tiles) n += tile.second.live();
  return n;
}

void VoxelAccumulator::clear() {
  impl_->scans.clear();
  impl_->tiles.clear();
  impl_->has_last = false;
  impl_->odometer_m = 0.0;
}

}  // namespace segmatch
