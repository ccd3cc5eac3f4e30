// Incremental voxel grid of a local cloud (see voxel_accumulator.h).
#include "segmatch/core/voxel_accumulator.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <stdexcept>
#include <unordered_map>

#include "seg_grid.h"

namespace segmatch {
namespace {

constexpr int kAxisBits = 21;
constexpr uint64_t kAxisMask = (uint64_t{1} << kAxisBits) - 1;
constexpr int64_t kAxisHalf = int64_t{1} << (kAxisBits - 1);
constexpr int kTileShift = 4;  // a tile is 16 x 16 voxel columns (1.6 m at 0.1 m)
constexpr uint64_t kEmpty = ~uint64_t{0};
constexpr uint32_t kNoVote = ~uint32_t{0};
constexpr double kFracScale = 4294967296.0;  // 2^32: position inside the voxel, 32.32 fixed point
constexpr double kMaxRangeM = 20000.0;       // farther from the sensor is refused (key wrap safety)
constexpr double kTileMarginM = 1e-3;        // tiles this close to the boundary are recomputed

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
    int64_t t = static_cast<int64_t>(q);
    t -= double(t) > q;  // floor, without the libm call
    out->v[a] = t;
    const double fr = (q - double(t)) * kFracScale;
    out->f[a] = std::min<int64_t>(std::max<int64_t>(static_cast<int64_t>(fr), 0), int64_t{0xFFFFFFFF});
  }
  return true;
}

inline uint64_t wrap_key(const int64_t v[3]) {
  return (static_cast<uint64_t>(v[0]) & kAxisMask) << (2 * kAxisBits) |
         (static_cast<uint64_t>(v[1]) & kAxisMask) << kAxisBits | (static_cast<uint64_t>(v[2]) & kAxisMask);
}

// The voxel coordinate congruent to the wrapped one nearest `centre`.
inline int64_t unwrap(uint64_t key, int axis, int64_t centre) {
  const uint64_t w = (key >> (kAxisBits * (2 - axis))) & kAxisMask;
  int64_t d = static_cast<int64_t>((w - static_cast<uint64_t>(centre)) & kAxisMask);
  if (d >= kAxisHalf) d -= int64_t{1} << kAxisBits;
  return centre + d;
}

struct Slot {
  uint64_t key;
  uint32_t n;
  uint32_t votes;  // head of the label vote list, kNoVote if none
  int64_t s[3];    // sums of the fixed-point positions inside the voxel
  double i;        // intensity sum
};
struct Vote {
  uint32_t label, count, next;
};

// Open addressing, linear probing, power-of-two capacity, at most 70 % used. A voxel whose
// count drops to 0 keeps its slot until the next rebuild, which keeps only live voxels.
class VoxelTable {
 public:
  explicit VoxelTable(size_t expected = 0) { allocate(expected); }
  size_t capacity() const { return slots_.size(); }
  size_t live() const { return live_; }
  const Slot& slot(size_t s) const { return slots_[s]; }
  size_t home(uint64_t key) const { return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> shift_); }
  void prefetch(uint64_t key) const { __builtin_prefetch(&slots_[home(key)]); }

  // Room for `more` insertions without a rebuild.
  void reserve_more(size_t more) {
    if (10 * (used_ + more) <= 7 * slots_.size()) return;
    rebuild(live_ + more);
  }

  // Adds (sign +1) or removes (-1) one point. reserve_more must have made room.
  void add(uint64_t key, const int64_t f[3], float intensity, uint32_t label, int sign) {
    size_t s = home(key);
    while (slots_[s].key != key) {
      if (slots_[s].key == kEmpty) {
        slots_[s].key = key;
        ++used_;
        break;
      }
      s = (s + 1) & mask_;
    }
    Slot& v = slots_[s];
    if (sign > 0) {
      if (v.n++ == 0) ++live_;
      v.s[0] += f[0], v.s[1] += f[1], v.s[2] += f[2];
      v.i += intensity;
    } else {
      if (--v.n == 0) --live_;
      v.s[0] -= f[0], v.s[1] -= f[1], v.s[2] -= f[2];
      v.i -= intensity;
    }
    if (label != 0) vote(v, label, sign);
  }

  // Majority non-zero label (ties: the smaller label; 0 if none), as detail::majority_label.
  uint32_t majority(const Slot& v) const {
    uint32_t best = 0, best_count = 0;
    for (uint32_t u = v.votes; u != kNoVote; u = votes_[u].next) {
      const Vote& x = votes_[u];
      if (x.count > best_count || (x.count == best_count && x.count > 0 && x.label < best)) {
        best = x.label;
        best_count = x.count;
      }
    }
    return best;
  }

  void clear() {
    allocate(0);
  }

 private:
  void vote(Slot& v, uint32_t label, int sign) {
    for (uint32_t u = v.votes; u != kNoVote; u = votes_[u].next)
      if (votes_[u].label == label) {
        votes_[u].count += sign;
        return;
      }
    // A removed point's label was voted when it was added, so only additions get here.
    votes_.push_back({label, 1u, v.votes});
    v.votes = static_cast<uint32_t>(votes_.size() - 1);
  }
  void allocate(size_t expected) {
    size_t capacity = 64;
    while (10 * expected > 7 * capacity / 2) capacity <<= 1;  // <= 35 % after (re)allocation
    slots_.assign(capacity, Slot{kEmpty, 0, kNoVote, {0, 0, 0}, 0.0});
    mask_ = capacity - 1;
    shift_ = 64;
    while ((size_t{1} << (64 - shift_)) < capacity) --shift_;
    used_ = live_ = 0;
    votes_.clear();
  }
  void rebuild(size_t expected) {
    std::vector<Slot> old = std::move(slots_);
    std::vector<Vote> old_votes = std::move(votes_);
    allocate(expected);
    for (const Slot& o : old) {
      if (o.key == kEmpty || o.n == 0) continue;
      size_t s = home(o.key);
      while (slots_[s].key != kEmpty) s = (s + 1) & mask_;
      Slot& v = slots_[s];
      v = o;
      v.votes = kNoVote;
      for (uint32_t u = o.votes; u != kNoVote; u = old_votes[u].next) {
        if (old_votes[u].count == 0) continue;
        votes_.push_back({old_votes[u].label, old_votes[u].count, v.votes});
        v.votes = static_cast<uint32_t>(votes_.size() - 1);
      }
      ++used_, ++live_;
    }
  }

  std::vector<Slot> slots_;
  std::vector<Vote> votes_;
  size_t mask_ = 0, used_ = 0, live_ = 0;
  int shift_ = 58;
};

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
};

// Adds (sign +1) or subtracts (-1) points [begin, end) into the table, computing the keys of
// a batch and prefetching their slots before touching any.
void sum_points(const PointCloud& points, const std::vector<uint32_t>& labels, size_t begin, size_t end,
                double leaf, int sign, VoxelTable* table) {
  constexpr size_t kBatch = 16;
  uint64_t keys[kBatch];
  int64_t frac[kBatch][3];
  uint32_t idx[kBatch];
  table->reserve_more(end - begin);
  for (size_t start = begin; start < end; start += kBatch) {
    const size_t stop = std::min(end, start + kBatch);
    size_t m = 0;
    for (size_t i = start; i < stop; ++i) {
      Voxelized v;
      if (!voxelize(points[i], leaf, &v)) continue;
      keys[m] = wrap_key(v.v);
      std::copy(v.f, v.f + 3, frac[m]);
      idx[m] = static_cast<uint32_t>(i);
      table->prefetch(keys[m++]);
    }
    for (size_t k = 0; k < m; ++k)
      table->add(keys[k], frac[k], points[idx[k]].intensity, labels.empty() ? 0u : labels[idx[k]], sign);
  }
}

inline uint64_t tile_key(int64_t x, int64_t y) {
  return static_cast<uint64_t>(x) << 32 ^ static_cast<uint32_t>(y);
}

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

  // Adds (+1) or subtracts (-1) a scan's points, tile by tile.
  void sum_scan(const Scan& s, int sign) {
    for (size_t t = 0; t + 1 < s.tiles.size(); ++t) {
      const uint64_t key = tile_key(s.tiles[t].x, s.tiles[t].y);
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
      if (sign < 0 && table->live() == 0) tiles.erase(key);
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
  scan.min_xy[0] = scan.min_xy[1] = std::numeric_limits<float>::max();
  scan.max_xy[0] = scan.max_xy[1] = std::numeric_limits<float>::lowest();
  for (uint32_t i : keep) {
    const Point& p = scan_sensor[i];
    const Eigen::Vector3d w = R * Eigen::Vector3d(p.x, p.y, p.z) + position;
    const Point q{float(w.x()), float(w.y()), float(w.z()), p.intensity};
    if (!detail::is_finite(q)) continue;  // LocalCloud keeps these, but voxel_filter ignores them
    if (std::abs(w.x() - position.x()) > kMaxRangeM || std::abs(w.y() - position.y()) > kMaxRangeM ||
        std::abs(w.z() - position.z()) > kMaxRangeM) {
      throw std::invalid_argument("VoxelAccumulator::add_scan: a point lies more than 20 km from the sensor");
    }
    world.push_back(q);
    if (labels) world_labels.push_back((*labels)[i]);
    scan.min_xy[0] = std::min(scan.min_xy[0], q.x);
    scan.min_xy[1] = std::min(scan.min_xy[1], q.y);
    scan.max_xy[0] = std::max(scan.max_xy[0], q.x);
    scan.max_xy[1] = std::max(scan.max_xy[1], q.y);
  }
  m.has_last = true;
  m.last_position = position;

  // Group the points by tile (stable radix sort on tile keys relative to the scan's first tile).
  const size_t n = world.size();
  std::vector<int64_t> tx(n), ty(n);
  int64_t lo[2] = {std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::max()};
  int64_t hi[2] = {std::numeric_limits<int64_t>::min(), std::numeric_limits<int64_t>::min()};
  for (size_t i = 0; i < n; ++i) {
    Voxelized v{};
    voxelize(world[i], m.leaf, &v);  // finite: checked above
    tx[i] = v.v[0] >> kTileShift;  // arithmetic shift: floor division
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

  // Drop (and subtract) the scans whose bounding box lies wholly outside, as LocalCloud::crop.
  const auto outside = [&](const Scan& s) {
    if (s.points.empty()) return true;
    const double nx = std::clamp(cx, double(s.min_xy[0]), double(s.max_xy[0]));
    const double ny = std::clamp(cy, double(s.min_xy[1]), double(s.max_xy[1]));
    return (nx - cx) * (nx - cx) + (ny - cy) * (ny - cy) > r2;
  };
  for (const Scan& s : m.scans)
    if (outside(s)) m.sum_scan(s, -1);
  m.scans.erase(std::remove_if(m.scans.begin(), m.scans.end(), outside), m.scans.end());
  if (m.scans.empty()) return {};

  // Tiles: 0 wholly outside, 1 wholly inside (every point passes the point test), 2 crossed
  // by the boundary. The margin covers the rounding of floor(v / leaf).
  const double tile_m = leaf * double(int64_t{1} << kTileShift);
  const double inner = radius - kTileMarginM, outer = radius + kTileMarginM;
  const auto classify = [&](int64_t x, int64_t y) {
    const double x0 = double(x) * tile_m, x1 = double(x + 1) * tile_m;
    const double y0 = double(y) * tile_m, y1 = double(y + 1) * tile_m;
    const double nx = std::clamp(cx, x0, x1) - cx, ny = std::clamp(cy, y0, y1) - cy;
    if (nx * nx + ny * ny > outer * outer) return 0;
    const double fx = std::max(std::abs(x0 - cx), std::abs(x1 - cx));
    const double fy = std::max(std::abs(y0 - cy), std::abs(y1 - cy));
    return (inner > 0 && fx * fx + fy * fy <= inner * inner) ? 1 : 2;
  };

  // The boundary tiles' voxels, from the raw points inside the cylinder.
  VoxelTable boundary;
  PointCloud ring;
  std::vector<uint32_t> ring_labels;
  for (const Scan& s : m.scans) {
    for (size_t t = 0; t + 1 < s.tiles.size(); ++t) {
      if (classify(s.tiles[t].x, s.tiles[t].y) != 2) continue;
      for (uint32_t i = s.tiles[t].begin; i < s.tiles[t + 1].begin; ++i) {
        const double dx = s.points[i].x - cx, dy = s.points[i].y - cy;
        if (dx * dx + dy * dy > r2) continue;  // LocalCloud::crop's test
        ring.push_back(s.points[i]);
        if (labels_out) ring_labels.push_back(s.labels.empty() ? 0u : s.labels[i]);
      }
    }
  }
  sum_points(ring, ring_labels, 0, ring.size(), leaf, +1, &boundary);

  // Occupied voxels of inside tiles (from the table) and of boundary tiles (recomputed).
  const int64_t centre[3] = {static_cast<int64_t>(std::floor(cx / leaf)), static_cast<int64_t>(std::floor(cy / leaf)),
                             static_cast<int64_t>(std::floor(T_world_sensor.translation().z() / leaf))};
  // Each voxel's point is computed while its table is read in slot order; only the points
  // (and voxel coordinates) are then permuted into key order.
  std::vector<int64_t> coords;  // x, y, z per voxel
  PointCloud points;
  std::vector<uint32_t> labels;
  const uint32_t min_points = static_cast<uint32_t>(m.voxel.min_points_per_voxel);
  const auto collect = [&](const VoxelTable& table) {
    for (size_t s = 0; s < table.capacity(); ++s) {
      const Slot& v = table.slot(s);
      if (v.key == kEmpty || v.n < min_points) continue;
      const double n = v.n;
      double p[3];
      for (int a = 0; a < 3; ++a) {
        const int64_t c = unwrap(v.key, a, centre[a]);
        coords.push_back(c);
        p[a] = (double(c) + double(v.s[a]) / kFracScale / n) * leaf;
      }
      points.push_back({float(p[0]), float(p[1]), float(p[2]), float(v.i / n)});
      if (labels_out) labels.push_back(table.majority(v));
    }
  };
  for (const auto& [key, table] : m.tiles) {
    const int64_t x = static_cast<int64_t>(key) >> 32;  // arithmetic shift undoes tile_key's
    const int64_t y = static_cast<int32_t>(static_cast<uint32_t>(key));
    if (classify(x, y) == 1) collect(table);
  }
  collect(boundary);

  // Voxel key order (x, then y, then z), as voxel_filter.
  const size_t count = points.size();
  int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::numeric_limits<int64_t>::max();
    hi[a] = std::numeric_limits<int64_t>::min();
  }
  for (size_t k = 0; k < count; ++k)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], coords[3 * k + a]), hi[a] = std::max(hi[a], coords[3 * k + a]);
  int bits[3] = {0, 0, 0};
  for (int a = 0; a < 3; ++a)
    while (count > 0 && (int64_t{1} << bits[a]) <= hi[a] - lo[a]) ++bits[a];
  std::vector<uint64_t> keys(count);
  std::vector<uint32_t> order(count);
  for (size_t k = 0; k < count; ++k) {
    uint64_t packed = 0;
    for (int a = 0; a < 3; ++a) packed = (packed << bits[a]) | static_cast<uint64_t>(coords[3 * k + a] - lo[a]);
    keys[k] = packed;
    order[k] = static_cast<uint32_t>(k);
  }
  detail::radix_sort(keys, order, std::max(bits[0] + bits[1] + bits[2], 1));

  PointCloud out(count);
  for (size_t k = 0; k < count; ++k) out[k] = points[order[k]];
  if (labels_out) {
    labels_out->resize(count);
    for (size_t k = 0; k < count; ++k) (*labels_out)[k] = labels[order[k]];
  }
  return out;
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
}

}  // namespace segmatch
