// Voxel grid filter (paper III-A, IV-A: leaf 0.1 m, a voxel is occupied with >= 2 points).
#include <algorithm>
#include <stdexcept>
#include <string>

#include "detail/seg_grid.h"
#include "segmatch/core/preprocess/preprocess.h"

namespace segmatch {

void VoxelGridConfig::validate() const {
  if (!(leaf_m > 0.0f) || !std::isfinite(leaf_m)) {
    throw std::invalid_argument("VoxelGridConfig.leaf_m must be positive");
  }
  if (min_points_per_voxel < 1) {
    throw std::invalid_argument("VoxelGridConfig.min_points_per_voxel must be >= 1");
  }
}

namespace {

// ---- voxel_filter: one pass over the points into a hash table of voxels.
// A local cloud holds millions of points (~7M for 60 m of HDL-64E scans every metre) but only
// ~0.5M voxels. Sorting the keys of all points (CellGrid::build) moves ~170 MB and then reads
// the points in voxel order, i.e. at random: ~0.5 s. Here the points are read once, in input
// order, and summed into a table of 32-byte slots (~24 MB); only occupied voxels are sorted.
// Every scan of the local cloud revisits most voxels, so ~40 % of the points still miss the
// caches; batches of slot prefetches overlap those misses.

// Voxel coordinates relative to a reference voxel near the first finite point, 21 bits per
// axis (+-2^20 voxels, +-104 km at 0.1 m); clouds reaching farther take the sorting path.
using detail::kPack21Half;
using detail::kPack21Mask;
constexpr uint64_t kEmpty = ~uint64_t{0};

// Packs the voxel of a point, relative to `centre` (a voxel near the first finite point). The
// voxel index must be floor(v / leaf) exactly as GridFrame::coord() computes it; the product
// with 1 / leaf used here is off by a few ulps, which can only matter within eps of a voxel
// boundary, and those rare points take the division. `frac` (0..1) is the position inside
// the voxel, summed for the centroid.
struct VoxelKeyer {
  double leaf, inv, centre[3], eps[3];
  // False if the point is not finite or beyond the key range.
  bool key(const Point& p, uint64_t* key, float frac[3]) const {
    const float v[3] = {p.x, p.y, p.z};
    int64_t cell[3];
    for (int a = 0; a < 3; ++a) {
      const double d = double(v[a]) * inv - centre[a];
      if (!(std::abs(d) < double(kPack21Half - 2))) return false;  // also guards the cast
      int64_t t = detail::fast_floor(d);
      double f = d - double(t);
      if (f < eps[a] || f > 1.0 - eps[a]) {
        const double q = double(v[a]) / leaf, c = std::floor(q);
        t = static_cast<int64_t>(c - centre[a]);
        f = std::min(std::max(q - c, 0.0), 0.99999994);
      }
      frac[a] = static_cast<float>(f);
      cell[a] = t;
    }
    *key = detail::pack21(cell[0], cell[1], cell[2]);
    return true;
  }
  // Coordinate of the voxel's corner (low side) on `axis`.
  double corner(uint64_t key, int axis) const { return (double(detail::unpack21(key, axis)) + centre[axis]) * leaf; }
};

// One voxel, two per cache line. The sums are of offsets from the voxel's corner (< leaf),
// where float keeps ~1e-9 m; absolute coordinates summed in float would lose millimetres.
struct alignas(32) VoxelSlot {
  uint64_t key;  // kEmpty: a free slot (pack21 keys use 63 bits)
  uint32_t n;
  float x, y, z, i;
  static VoxelSlot free_slot() { return {kEmpty, 0, 0.f, 0.f, 0.f, 0.f}; }
  bool is_free() const { return key == kEmpty; }
};
using VoxelTable = detail::OpenTable<VoxelSlot>;

VoxelSlot& find_or_insert(VoxelTable& table, uint64_t key) {
  bool claimed = false;
  size_t s;
  while ((s = table.find_or_claim(key, &claimed)) == VoxelTable::kNone) table.grow();
  return table[s];
}

// Reference voxel for the keys; false if the first finite point is too far from the origin.
bool make_keyer(const PointCloud& cloud, double leaf, VoxelKeyer* k) {
  k->leaf = leaf;
  k->inv = 1.0 / leaf;
  size_t first = 0;
  while (first < cloud.size() && !detail::is_finite(cloud[first])) ++first;
  for (int a = 0; a < 3; ++a) {
    const float v = first < cloud.size() ? (&cloud[first].x)[a] : 0.f;
    k->centre[a] = std::floor(double(v) * k->inv);
    if (!(std::abs(k->centre[a]) < 1e15)) return false;
    // Far above the few-ulp error of the product at the largest |v / leaf| in range.
    k->eps[a] = 1e-12 * (std::abs(k->centre[a]) + double(kPack21Half) + 1.0);
  }
  return true;
}

// Sums every finite point into its voxel. The keys of a batch are computed and their slots
// prefetched before any slot is touched. Returns false if a point is beyond the key range.
bool accumulate_voxels(const PointCloud& cloud, const VoxelKeyer& keyer, VoxelTable* table) {
  constexpr size_t kBatch = 32;
  uint64_t keys[kBatch];
  float frac[kBatch][4];
  for (size_t start = 0; start < cloud.size(); start += kBatch) {
    const size_t end = std::min(cloud.size(), start + kBatch);
    size_t m = 0;
    for (size_t i = start; i < end; ++i) {
      if (!keyer.key(cloud[i], &keys[m], frac[m])) {
        if (detail::is_finite(cloud[i])) return false;
        continue;
      }
      frac[m][3] = cloud[i].intensity;
      table->prefetch(keys[m++]);
    }
    for (size_t k = 0; k < m; ++k) {
      VoxelSlot& s = find_or_insert(*table, keys[k]);
      ++s.n;
      s.x += frac[k][0];
      s.y += frac[k][1];
      s.z += frac[k][2];
      s.i += frac[k][3];
    }
  }
  return true;
}

// Slots of the voxels with at least min_points points, sorted by key (x, then y, then z).
std::vector<uint32_t> occupied_in_key_order(const VoxelTable& table, int min_points) {
  std::vector<uint32_t> slots;
  uint64_t lo[3] = {kPack21Mask, kPack21Mask, kPack21Mask}, hi[3] = {0, 0, 0};
  for (size_t s = 0; s < table.capacity(); ++s) {
    const VoxelSlot& v = table[s];
    if (v.is_free() || static_cast<int>(v.n) < min_points) continue;
    slots.push_back(static_cast<uint32_t>(s));
    for (int a = 0; a < 3; ++a) {
      const uint64_t c = detail::field21(v.key, a);
      lo[a] = std::min(lo[a], c);
      hi[a] = std::max(hi[a], c);
    }
  }
  // Re-packed with just enough bits per axis, so the radix sort takes few passes.
  int bits[3] = {0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    while (!slots.empty() && (uint64_t{1} << bits[a]) <= hi[a] - lo[a]) ++bits[a];
  }
  std::vector<uint64_t> keys(slots.size());
  for (size_t k = 0; k < slots.size(); ++k) {
    uint64_t packed = 0;
    for (int a = 0; a < 3; ++a) {
      const uint64_t c = detail::field21(table[slots[k]].key, a);
      packed = (packed << bits[a]) | (c - lo[a]);
    }
    keys[k] = packed;
  }
  detail::radix_sort(keys, slots, std::max(bits[0] + bits[1] + bits[2], 1));
  return slots;
}

// Majority label of each output voxel: the points are looked up again and grouped by voxel.
std::vector<uint32_t> voxel_labels(const PointCloud& cloud, const VoxelKeyer& keyer, const VoxelTable& table,
                                   const std::vector<uint32_t>& slots, const std::vector<uint32_t>& labels) {
  constexpr uint32_t kNone = detail::FlatHashMap::kMissing;
  std::vector<uint32_t> out_of_slot(table.capacity(), kNone), begin(slots.size() + 1, 0);
  for (size_t k = 0; k < slots.size(); ++k) {
    out_of_slot[slots[k]] = static_cast<uint32_t>(k);
    begin[k + 1] = begin[k] + table[slots[k]].n;
  }
  std::vector<uint32_t> members(begin.back()), fill(begin.begin(), begin.end() - 1);
  for (size_t i = 0; i < cloud.size(); ++i) {
    uint64_t key;
    float frac[3];
    if (!keyer.key(cloud[i], &key, frac)) continue;
    const uint32_t k = out_of_slot[table.find(key)];
    if (k != kNone) members[fill[k]++] = static_cast<uint32_t>(i);
  }
  std::vector<uint32_t> out(slots.size()), scratch;
  for (size_t k = 0; k < slots.size(); ++k) {
    out[k] = detail::majority_label(labels, &members[begin[k]], begin[k + 1] - begin[k], &scratch);
  }
  return out;
}

// The general path: sorts the keys of all points (any extent that fits in 64 bits).
PointCloud voxel_filter_sorted(const PointCloud& cloud, const VoxelGridConfig& config,
                               const std::vector<uint32_t>* labels, std::vector<uint32_t>* labels_out) {
  const detail::CellGrid grid = detail::CellGrid::build(cloud, config.leaf_m, false, "VoxelGridConfig.leaf_m", false);
  PointCloud out;
  out.reserve(grid.cell_count());
  std::vector<uint32_t> scratch;
  for (size_t c = 0; c < grid.cell_count(); ++c) {
    const uint32_t b = grid.begin[c], e = grid.begin[c + 1];
    if (static_cast<int>(e - b) < config.min_points_per_voxel) continue;
    double sx = 0, sy = 0, sz = 0, si = 0;
    for (uint32_t k = b; k < e; ++k) {
      const Point& p = cloud[grid.order[k]];
      sx += p.x;
      sy += p.y;
      sz += p.z;
      si += p.intensity;
    }
    const double inv = 1.0 / (e - b);
    out.push_back({float(sx * inv), float(sy * inv), float(sz * inv), float(si * inv)});
    if (labels && labels_out) {
      labels_out->push_back(detail::majority_label(*labels, &grid.order[b], e - b, &scratch));
    }
  }
  return out;
}

}  // namespace

PointCloud voxel_filter(const PointCloud& cloud, const VoxelGridConfig& config, const std::vector<uint32_t>* labels,
                        std::vector<uint32_t>* labels_out) {
  config.validate();
  if (labels && labels->size() != cloud.size()) {
    throw std::invalid_argument("voxel_filter: labels size differs from cloud size");
  }
  if (labels_out) labels_out->clear();
  if (cloud.empty()) return {};
  VoxelKeyer keyer;
  // A local cloud has ~16 points per voxel; the table grows if there are more voxels.
  VoxelTable table(cloud.size() / 20 + 1);
  if (!make_keyer(cloud, config.leaf_m, &keyer) || !accumulate_voxels(cloud, keyer, &table)) {
    return voxel_filter_sorted(cloud, config, labels, labels_out);
  }
  const std::vector<uint32_t> slots = occupied_in_key_order(table, config.min_points_per_voxel);
  PointCloud out;
  out.reserve(slots.size());
  for (uint32_t s : slots) {
    const VoxelSlot& v = table[s];
    const double n = v.n;
    out.push_back({float(keyer.corner(v.key, 0) + double(v.x) / n * keyer.leaf),
                   float(keyer.corner(v.key, 1) + double(v.y) / n * keyer.leaf),
                   float(keyer.corner(v.key, 2) + double(v.z) / n * keyer.leaf), float(double(v.i) / n)});
  }
  if (labels && labels_out) *labels_out = voxel_labels(cloud, keyer, table, slots, *labels);
  return out;
}

}  // namespace segmatch
