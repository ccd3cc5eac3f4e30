// Private helpers shared by the voxel grid, ground removal and the segmenters: integer
// grid keys, a stable LSD radix sort of 64-bit keys, a flat hash map (open_table.h) and a
// sparse 3D cell grid for fixed-radius neighbour queries. Nothing here allocates per point
// beyond a few flat arrays, which is what keeps the pipeline inside its time budget.
// Implemented in seg_grid.cpp.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "detail/open_table.h"
#include "segmatch/core/common/types.h"

namespace segmatch {
namespace detail {

inline bool is_finite(const Point& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

// std::floor(q) as an integer, for |q| < 2^63, without the libm call std::floor is on
// x86-64 without SSE4.1 (it was a measurable share of the voxel and cell keys).
inline int64_t fast_floor(double q) {
  const int64_t t = static_cast<int64_t>(q);
  return t - (static_cast<double>(t) > q);
}

// Three cell coordinates in one key, 21 bits each (a in the high bits), offset by 2^20 so that
// cells -2^20 .. 2^20 - 1 keep their order; coordinates beyond wrap (callers bound them).
constexpr int kPack21Bits = 21;
constexpr uint64_t kPack21Mask = (uint64_t{1} << kPack21Bits) - 1;
constexpr int64_t kPack21Half = int64_t{1} << (kPack21Bits - 1);
inline uint64_t pack21(int64_t a, int64_t b, int64_t c) {
  const auto u = [&](int64_t v) { return static_cast<uint64_t>(v + kPack21Half) & kPack21Mask; };
  return (u(a) << (2 * kPack21Bits)) | (u(b) << kPack21Bits) | u(c);
}
// Field 0 (a), 1 (b) or 2 (c) of a pack21() key, still offset (0 .. 2^21 - 1, in cell order).
inline uint64_t field21(uint64_t key, int field) { return (key >> (kPack21Bits * (2 - field))) & kPack21Mask; }
// The cell coordinate pack21() stored in field 0, 1 or 2.
inline int64_t unpack21(uint64_t key, int field) { return static_cast<int64_t>(field21(key, field)) - kPack21Half; }

// Two coordinates in one key, x in the high 32 bits: for y in [0, 2^32) the keys of one x are
// contiguous and ordered by y, and x + dx is key + (dx << 32).
inline uint64_t pack_xy(int64_t x, int64_t y) { return static_cast<uint64_t>(x) << 32 ^ static_cast<uint32_t>(y); }
// The x and y of a pack_xy() key, for -2^31 <= x, y < 2^31.
inline int64_t unpack_x(uint64_t key) { return static_cast<int64_t>(key) >> 32; }  // arithmetic shift
inline int64_t unpack_y(uint64_t key) { return static_cast<int32_t>(static_cast<uint32_t>(key)); }

// A sensor point in the world frame: rotated and translated in double, stored in float. LocalCloud
// and VoxelAccumulator both admit scans through this and subsample_indices(), so that they hold
// the same points.
inline Point world_point(const Point& p, const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  const Eigen::Vector3d w = R * Eigen::Vector3d(p.x, p.y, p.z) + t;
  return {float(w.x()), float(w.y()), float(w.z()), p.intensity};
}

// A scan's horizontal bounding box (for dropping whole scans), empty until grown.
inline void reset_xy_bounds(float min_xy[2], float max_xy[2]) {
  min_xy[0] = min_xy[1] = std::numeric_limits<float>::max();
  max_xy[0] = max_xy[1] = std::numeric_limits<float>::lowest();
}
inline void grow_xy_bounds(const Point& q, float min_xy[2], float max_xy[2]) {
  min_xy[0] = std::min(min_xy[0], q.x);
  min_xy[1] = std::min(min_xy[1], q.y);
  max_xy[0] = std::max(max_xy[0], q.x);
  max_xy[1] = std::max(max_xy[1], q.y);
}

// Whether a held scan leaves the local cloud at a crop around (cx, cy): its bounding box lies
// wholly outside the cylinder, or it was added more than max_scan_age_m of driving before the
// last added scan (0: no age limit). LocalCloud and VoxelAccumulator both drop scans by this.
inline bool scan_leaves(const float min_xy[2], const float max_xy[2], bool empty, double added_at_m, double odometer_m,
                        double cx, double cy, double radius_m, double max_scan_age_m) {
  if (empty) return true;
  if (max_scan_age_m > 0.0 && odometer_m - added_at_m > max_scan_age_m) return true;
  const double nx = std::clamp(cx, double(min_xy[0]), double(max_xy[0]));
  const double ny = std::clamp(cy, double(min_xy[1]), double(max_xy[1]));
  return (nx - cx) * (nx - cx) + (ny - cy) * (ny - cy) > radius_m * radius_m;
}

// Stable LSD radix sort of (key << 32 | value) words by key, the lowest `key_bits` (<= 32) bits
// of the high half.
void sort_packed(std::vector<uint64_t>& words, int key_bits);

// Stable LSD radix sort of `keys` (only the lowest `key_bits` bits are significant),
// permuting `values` alongside: sort_packed() for keys of up to 32 bits, 11-bit digits beyond.
void radix_sort(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits);

// Maps 64-bit keys to 32-bit values (an OpenTable of key-value slots). No erase.
class FlatHashMap {
 public:
  static constexpr uint32_t kMissing = std::numeric_limits<uint32_t>::max();

  explicit FlatHashMap(size_t expected_size = 0) : table_(expected_size) {}
  // Empties the map and sizes it for `expected_size` keys.
  void reserve(size_t expected_size) { table_ = OpenTable<Entry>(expected_size); }
  // Inserts key -> value (value != kMissing) unless present; returns the stored value.
  uint32_t insert(uint64_t key, uint32_t value) {
    bool claimed = false;
    size_t s;
    while ((s = table_.find_or_claim(key, &claimed)) == OpenTable<Entry>::kNone) table_.grow();
    if (claimed) table_[s].value = value;
    return table_[s].value;
  }
  uint32_t find(uint64_t key) const {
    const size_t s = table_.find(key);
    return s == OpenTable<Entry>::kNone ? kMissing : table_[s].value;
  }
  size_t size() const { return table_.used(); }

 private:
  struct Entry {
    uint64_t key;
    uint32_t value;  // kMissing: a free slot
    static Entry free_slot() { return {0, kMissing}; }
    bool is_free() const { return value == kMissing; }
  };
  OpenTable<Entry> table_;
};

// Integer cell coordinates of points on a regular grid aligned with the world origin
// (cell i spans [i, i + 1) * cell_m, as in PCL), offset by the cell of the minimum corner of
// the (finite) points, packed into one key with just enough bits per axis; keys therefore
// sort lexicographically by (x, y, z). With `planar` the z axis is ignored (columns).
struct GridFrame {
  double cell_m = 1.0;
  int64_t base[3] = {0, 0, 0};    // cell coordinate of the minimum corner
  int64_t extent[3] = {1, 1, 1};  // cells per axis
  int bits[3] = {1, 1, 0};
  int total_bits = 2;

  // Throws std::invalid_argument naming `field` if the cloud does not fit into 64 bits.
  static GridFrame fit(const PointCloud& cloud, double cell_m, bool planar, const char* field);
  int64_t coord(float v, int axis) const { return static_cast<int64_t>(std::floor(double(v) / cell_m)) - base[axis]; }
  bool inside(int64_t ix, int64_t iy, int64_t iz) const {
    return ix >= 0 && iy >= 0 && iz >= 0 && ix < extent[0] && iy < extent[1] && iz < extent[2];
  }
  uint64_t pack(int64_t ix, int64_t iy, int64_t iz) const {
    return (static_cast<uint64_t>(ix) << (bits[1] + bits[2])) | (static_cast<uint64_t>(iy) << bits[2]) |
           static_cast<uint64_t>(iz);
  }
  uint64_t key_of(const Point& p) const { return pack(coord(p.x, 0), coord(p.y, 1), bits[2] ? coord(p.z, 2) : 0); }
  // key_of() with fast_floor: the same key (the same quotient, floored the same).
  uint64_t fast_key(const Point& p) const {
    const auto c = [&](float v, int axis) { return fast_floor(double(v) / cell_m) - base[axis]; };
    return pack(c(p.x, 0), c(p.y, 1), bits[2] ? c(p.z, 2) : 0);
  }
};

// Points bucketed into cells: `order` lists point indices grouped by cell (cells sorted by
// key, points of a cell in input order), cell c spans order[begin[c] .. begin[c + 1]).
// Non-finite points are left out.
struct CellGrid {
  GridFrame frame;
  std::vector<uint32_t> order;
  std::vector<uint32_t> begin;       // size cells + 1
  std::vector<uint64_t> cell_key;    // size cells
  std::vector<uint32_t> point_cell;  // cell of each input point (kMissing if non-finite)
  FlatHashMap lookup;                // key -> cell index

  // with_lookup = false skips the hash map (cell_at() is then unusable).
  static CellGrid build(const PointCloud& cloud, double cell_m, bool planar, const char* field,
                        bool with_lookup = true);
  size_t cell_count() const { return cell_key.size(); }
  // Cell index at integer coordinates or kMissing.
  uint32_t cell_at(int64_t ix, int64_t iy, int64_t iz) const {
    if (!frame.inside(ix, iy, iz)) return FlatHashMap::kMissing;
    return lookup.find(frame.pack(ix, iy, iz));
  }
  void cell_coords(uint32_t cell, int64_t* ix, int64_t* iy, int64_t* iz) const {
    const uint64_t k = cell_key[cell];
    *iz = static_cast<int64_t>(k & ((uint64_t{1} << frame.bits[2]) - 1));
    *iy = static_cast<int64_t>((k >> frame.bits[2]) & ((uint64_t{1} << frame.bits[1]) - 1));
    *ix = static_cast<int64_t>(k >> (frame.bits[1] + frame.bits[2]));
  }
};

// For every cell of a 3D grid, the indices of its 27 neighbour cells (itself included;
// kMissing if empty): entry c * 27 + (dx + 1) * 9 + (dy + 1) * 3 + (dz + 1). Built by one
// sweep over the sorted cells with a cursor per neighbour column, no hashing. Entries
// above 13 are the neighbours lexicographically after the cell itself.
constexpr int kNeighbourCells = 27;
constexpr int kSelfCell = 13;
std::vector<uint32_t> neighbour_table(const CellGrid& grid);

// Most frequent non-zero label among `labels[indices]`; ties go to the smaller label; 0 if
// none. `scratch` is reused between calls.
uint32_t majority_label(const std::vector<uint32_t>& labels, const uint32_t* indices, size_t count,
                        std::vector<uint32_t>* scratch);

// Indices of the finite points of a scan, keeping only the first point of every occupied cube
// of edge leaf_m (leaf_m <= 0: all finite points), in input order. LocalCloud and
// VoxelAccumulator admit scans through this one function so that they hold the same points.
std::vector<uint32_t> subsample_indices(const PointCloud& scan, double leaf_m);

}  // namespace detail
}  // namespace segmatch
