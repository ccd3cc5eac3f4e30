// Voxel grid filter (paper III-A, IV-A: leaf 0.1 m, a voxel is occupied with >= 2 points)
// and the private grid helpers of seg_grid.h.
#include <algorithm>
#include <stdexcept>
#include <string>

#include "seg_grid.h"
#include "segmatch/core/preprocess.h"

namespace segmatch {
namespace detail {

namespace {

constexpr int kDigitBits = 11;
constexpr size_t kBuckets = size_t{1} << kDigitBits;

// One counting-sort pass on the digit at `shift` of `keys`, into `out`.
template <typename Fn>
void radix_pass(const std::vector<uint64_t>& keys, std::vector<uint64_t>& out, int shift,
                std::vector<uint32_t>& count, Fn&& moved) {
  std::fill(count.begin(), count.end(), 0u);
  for (uint64_t k : keys) ++count[(k >> shift) & (kBuckets - 1)];
  uint32_t sum = 0;
  for (auto& c : count) {
    const uint32_t c0 = c;
    c = sum;
    sum += c0;
  }
  for (size_t i = 0; i < keys.size(); ++i) {
    const uint32_t dst = count[(keys[i] >> shift) & (kBuckets - 1)]++;
    out[dst] = keys[i];
    moved(i, dst);
  }
}

}  // namespace

void radix_sort(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits) {
  const size_t n = keys.size();
  std::vector<uint32_t> count(kBuckets);
  std::vector<uint64_t> tmp(n);
  if (key_bits <= 32) {  // pack key and value into one word: half the memory traffic
    for (size_t i = 0; i < n; ++i) keys[i] = (keys[i] << 32) | values[i];
    for (int shift = 32; shift < 32 + key_bits; shift += kDigitBits) {
      radix_pass(keys, tmp, shift, count, [](size_t, uint32_t) {});
      keys.swap(tmp);
    }
    for (size_t i = 0; i < n; ++i) {
      values[i] = static_cast<uint32_t>(keys[i]);
      keys[i] >>= 32;
    }
    return;
  }
  std::vector<uint32_t> values_tmp(n);
  for (int shift = 0; shift < key_bits; shift += kDigitBits) {
    radix_pass(keys, tmp, shift, count,
               [&](size_t i, uint32_t dst) { values_tmp[dst] = values[i]; });
    keys.swap(tmp);
    values.swap(values_tmp);
  }
}

std::vector<uint32_t> neighbour_table(const CellGrid& grid) {
  const size_t n = grid.cell_count();
  const GridFrame& f = grid.frame;
  std::vector<uint32_t> table(n * kNeighbourCells, FlatHashMap::kMissing);
  size_t cursor[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};  // one per neighbour column (dx, dy)
  for (size_t c = 0; c < n; ++c) {
    int64_t x, y, z;
    grid.cell_coords(static_cast<uint32_t>(c), &x, &y, &z);
    for (int col = 0; col < 9; ++col) {
      const int64_t nx = x + col / 3 - 1, ny = y + col % 3 - 1;
      if (!f.inside(nx, ny, 0)) continue;
      // Targets grow with c (cells are sorted), so the cursor only moves forward.
      const uint64_t first = f.pack(nx, ny, std::max<int64_t>(z - 1, 0));
      size_t& k = cursor[col];
      while (k < n && grid.cell_key[k] < first) ++k;
      for (size_t j = k; j < n && j < k + 3; ++j) {
        int64_t cx, cy, cz;
        grid.cell_coords(static_cast<uint32_t>(j), &cx, &cy, &cz);
        if (cx != nx || cy != ny || cz > z + 1) break;
        table[c * kNeighbourCells + col * 3 + (cz - z + 1)] = static_cast<uint32_t>(j);
      }
    }
  }
  return table;
}

void FlatHashMap::reserve(size_t expected_size) {
  size_t capacity = 16;
  while (capacity < 2 * expected_size) capacity <<= 1;
  keys_.assign(capacity, 0);
  values_.assign(capacity, kMissing);
  mask_ = capacity - 1;
  size_ = 0;
}

uint32_t FlatHashMap::insert(uint64_t key, uint32_t value) {
  if (2 * (size_ + 1) > keys_.size()) {  // grow, keep load factor <= 1/2
    std::vector<uint64_t> old_keys = std::move(keys_);
    std::vector<uint32_t> old_values = std::move(values_);
    reserve(old_keys.size());
    for (size_t i = 0; i < old_keys.size(); ++i) {
      if (old_values[i] != kMissing) insert(old_keys[i], old_values[i]);
    }
  }
  size_t slot = hash(key) & mask_;
  while (values_[slot] != kMissing) {
    if (keys_[slot] == key) return values_[slot];
    slot = (slot + 1) & mask_;
  }
  keys_[slot] = key;
  values_[slot] = value;
  ++size_;
  return value;
}

static int bits_for(int64_t extent) {
  int b = 0;
  while ((int64_t{1} << b) < extent) ++b;
  return b;
}

GridFrame GridFrame::fit(const PointCloud& cloud, double cell_m, bool planar, const char* field) {
  GridFrame f;
  f.cell_m = cell_m;
  // Float bounds (exact: converting to double commutes with min / max), branch-free per point.
  float lo_f[3] = {0.f, 0.f, 0.f}, hi_f[3] = {0.f, 0.f, 0.f};
  size_t i = 0;
  while (i < cloud.size() && !is_finite(cloud[i])) ++i;
  if (i < cloud.size()) {
    const Point& p0 = cloud[i];
    float lo0 = p0.x, lo1 = p0.y, lo2 = p0.z, hi0 = p0.x, hi1 = p0.y, hi2 = p0.z;
    for (; i < cloud.size(); ++i) {
      const Point& p = cloud[i];
      if (!is_finite(p)) continue;
      lo0 = std::min(lo0, p.x), lo1 = std::min(lo1, p.y), lo2 = std::min(lo2, p.z);
      hi0 = std::max(hi0, p.x), hi1 = std::max(hi1, p.y), hi2 = std::max(hi2, p.z);
    }
    lo_f[0] = lo0, lo_f[1] = lo1, lo_f[2] = lo2, hi_f[0] = hi0, hi_f[1] = hi1, hi_f[2] = hi2;
  }
  const double lo[3] = {lo_f[0], lo_f[1], lo_f[2]}, hi[3] = {hi_f[0], hi_f[1], hi_f[2]};
  f.total_bits = 0;
  for (int a = 0; a < 3; ++a) {
    const double first = std::floor(lo[a] / cell_m);
    const double cells = std::floor(hi[a] / cell_m) - first + 1.0;
    if (!(cells <= double(int64_t{1} << 40))) {
      throw std::invalid_argument(std::string(field) + " too small for the cloud extent");
    }
    f.base[a] = static_cast<int64_t>(first);
    f.extent[a] = (planar && a == 2) ? 1 : static_cast<int64_t>(cells);
    f.bits[a] = bits_for(f.extent[a]);
    f.total_bits += f.bits[a];
  }
  if (f.total_bits > 64) {
    throw std::invalid_argument(std::string(field) + " too small for the cloud extent");
  }
  return f;
}

CellGrid CellGrid::build(const PointCloud& cloud, double cell_m, bool planar, const char* field,
                         bool with_lookup) {
  CellGrid g;
  g.frame = GridFrame::fit(cloud, cell_m, planar, field);
  std::vector<uint64_t> keys;
  keys.reserve(cloud.size());
  g.order.reserve(cloud.size());
  g.point_cell.assign(cloud.size(), FlatHashMap::kMissing);
  for (size_t i = 0; i < cloud.size(); ++i) {
    if (!is_finite(cloud[i])) continue;
    keys.push_back(g.frame.fast_key(cloud[i]));
    g.order.push_back(static_cast<uint32_t>(i));
  }
  radix_sort(keys, g.order, g.frame.total_bits);
  for (size_t i = 0; i < keys.size(); ++i) {
    if (i == 0 || keys[i] != keys[i - 1]) {
      g.cell_key.push_back(keys[i]);
      g.begin.push_back(static_cast<uint32_t>(i));
    }
    g.point_cell[g.order[i]] = static_cast<uint32_t>(g.cell_key.size() - 1);
  }
  g.begin.push_back(static_cast<uint32_t>(keys.size()));
  if (with_lookup) {  // sized by cells, not points: a compact table keeps lookups in cache
    g.lookup.reserve(g.cell_key.size());
    for (size_t c = 0; c < g.cell_key.size(); ++c) g.lookup.insert(g.cell_key[c], uint32_t(c));
  }
  return g;
}

uint32_t majority_label(const std::vector<uint32_t>& labels, const uint32_t* indices, size_t count,
                        std::vector<uint32_t>* scratch) {
  scratch->clear();
  for (size_t i = 0; i < count; ++i) {
    const uint32_t l = labels[indices[i]];
    if (l != 0) scratch->push_back(l);
  }
  if (scratch->empty()) return 0;
  std::sort(scratch->begin(), scratch->end());
  uint32_t best = 0;
  size_t best_run = 0;
  for (size_t i = 0; i < scratch->size();) {
    size_t j = i;
    while (j < scratch->size() && (*scratch)[j] == (*scratch)[i]) ++j;
    if (j - i > best_run) {  // strict: ties keep the smaller label
      best_run = j - i;
      best = (*scratch)[i];
    }
    i = j;
  }
  return best;
}

}  // namespace detail

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
constexpr int kAxisBits = 21;
constexpr int64_t kAxisHalf = int64_t{1} << (kAxisBits - 1);
constexpr uint64_t kAxisMask = (uint64_t{1} << kAxisBits) - 1;
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
    uint64_t k = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = double(v[a]) * inv - centre[a];
      if (!(std::abs(d) < double(kAxisHalf - 2))) return false;  // also guards the cast
      int64_t t = detail::fast_floor(d);
      double f = d - double(t);
      if (f < eps[a] || f > 1.0 - eps[a]) {
        const double q = double(v[a]) / leaf, c = std::floor(q);
        t = static_cast<int64_t>(c - centre[a]);
        f = std::min(std::max(q - c, 0.0), 0.99999994);
      }
      frac[a] = static_cast<float>(f);
      k = (k << kAxisBits) | static_cast<uint64_t>(t + kAxisHalf);
    }
    *key = k;
    return true;
  }
  // Coordinate of the voxel's corner (low side) on `axis`.
  double corner(uint64_t key, int axis) const {
    const int64_t t = static_cast<int64_t>((key >> (kAxisBits * (2 - axis))) & kAxisMask);
    return (double(t - kAxisHalf) + centre[axis]) * leaf;
  }
};

// One voxel, two per cache line. The sums are of offsets from the voxel's corner (< leaf),
// where float keeps ~1e-9 m; absolute coordinates summed in float would lose millimetres.
struct alignas(32) VoxelSlot {
  uint64_t key;
  uint32_t n;
  float x, y, z, i;
};

// Open addressing with linear probing, at most 70 % full.
class VoxelTable {
 public:
  explicit VoxelTable(size_t capacity) : slots_(std::max<size_t>(capacity, 64), kFree) {}
  size_t capacity() const { return slots_.size(); }
  const VoxelSlot& slot(size_t s) const { return slots_[s]; }
  // Multiplicative hash, reduced to [0, capacity) by a multiply instead of a modulo.
  size_t home(uint64_t key) const {
    return static_cast<size_t>((((key * 0x9E3779B97F4A7C15ull) >> 32) * slots_.size()) >> 32);
  }
  VoxelSlot& find_or_insert(uint64_t key) {
    size_t s = home(key);
    while (slots_[s].key != key) {
      if (slots_[s].key == kEmpty) {
        slots_[s].key = key;
        ++size_;
        break;
      }
      if (++s == slots_.size()) s = 0;
    }
    return slots_[s];
  }
  size_t find(uint64_t key) const {  // the key must be present
    size_t s = home(key);
    while (slots_[s].key != key) s = s + 1 == slots_.size() ? 0 : s + 1;
    return s;
  }
  // Room for `more` insertions without exceeding the load limit.
  void reserve_more(size_t more) {
    if (10 * (size_ + more) <= 7 * slots_.size()) return;
    std::vector<VoxelSlot> old(2 * slots_.size() + more, kFree);
    old.swap(slots_);
    size_ = 0;
    for (const VoxelSlot& o : old) {
      if (o.key != kEmpty) find_or_insert(o.key) = o;
    }
  }

 private:
  static constexpr VoxelSlot kFree = {kEmpty, 0, 0.f, 0.f, 0.f, 0.f};
  std::vector<VoxelSlot> slots_;
  size_t size_ = 0;
};

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
    k->eps[a] = 1e-12 * (std::abs(k->centre[a]) + double(kAxisHalf) + 1.0);
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
    table->reserve_more(kBatch);
    size_t m = 0;
    for (size_t i = start; i < end; ++i) {
      if (!keyer.key(cloud[i], &keys[m], frac[m])) {
        if (detail::is_finite(cloud[i])) return false;
        continue;
      }
      frac[m][3] = cloud[i].intensity;
      __builtin_prefetch(&table->slot(table->home(keys[m++])));
    }
    for (size_t k = 0; k < m; ++k) {
      VoxelSlot& s = table->find_or_insert(keys[k]);
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
  uint64_t lo[3] = {kAxisMask, kAxisMask, kAxisMask}, hi[3] = {0, 0, 0};
  for (size_t s = 0; s < table.capacity(); ++s) {
    const VoxelSlot& v = table.slot(s);
    if (v.key == kEmpty || static_cast<int>(v.n) < min_points) continue;
    slots.push_back(static_cast<uint32_t>(s));
    for (int a = 0; a < 3; ++a) {
      const uint64_t c = (v.key >> (kAxisBits * (2 - a))) & kAxisMask;
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
      const uint64_t c = (table.slot(slots[k]).key >> (kAxisBits * (2 - a))) & kAxisMask;
      packed = (packed << bits[a]) | (c - lo[a]);
    }
    keys[k] = packed;
  }
  detail::radix_sort(keys, slots, std::max(bits[0] + bits[1] + bits[2], 1));
  return slots;
}

// Majority label of each output voxel: the points are looked up again and grouped by voxel.
std::vector<uint32_t> voxel_labels(const PointCloud& cloud, const VoxelKeyer& keyer,
                                   const VoxelTable& table, const std::vector<uint32_t>& slots,
                                   const std::vector<uint32_t>& labels) {
  constexpr uint32_t kNone = detail::FlatHashMap::kMissing;
  std::vector<uint32_t> out_of_slot(table.capacity(), kNone), begin(slots.size() + 1, 0);
  for (size_t k = 0; k < slots.size(); ++k) {
    out_of_slot[slots[k]] = static_cast<uint32_t>(k);
    begin[k + 1] = begin[k] + table.slot(slots[k]).n;
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
                               const std::vector<uint32_t>* labels,
                               std::vector<uint32_t>* labels_out) {
  const detail::CellGrid grid =
      detail::CellGrid::build(cloud, config.leaf_m, false, "VoxelGridConfig.leaf_m", false);
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

PointCloud voxel_filter(const PointCloud& cloud, const VoxelGridConfig& config,
                        const std::vector<uint32_t>* labels, std::vector<uint32_t>* labels_out) {
  config.validate();
  if (labels && labels->size() != cloud.size()) {
    throw std::invalid_argument("voxel_filter: labels size differs from cloud size");
  }
  if (labels_out) labels_out->clear();
  if (cloud.empty()) return {};
  VoxelKeyer keyer;
  // A local cloud has ~16 points per voxel; the table grows if there are more voxels.
  VoxelTable table(cloud.size() / 10 + 1);
  if (!make_keyer(cloud, config.leaf_m, &keyer) || !accumulate_voxels(cloud, keyer, &table)) {
    return voxel_filter_sorted(cloud, config, labels, labels_out);
  }
  const std::vector<uint32_t> slots = occupied_in_key_order(table, config.min_points_per_voxel);
  PointCloud out;
  out.reserve(slots.size());
  for (uint32_t s : slots) {
    const VoxelSlot& v = table.slot(s);
    const double n = v.n;
    out.push_back({float(keyer.corner(v.key, 0) + double(v.x) / n * keyer.leaf),
                   float(keyer.corner(v.key, 1) + double(v.y) / n * keyer.leaf),
                   float(keyer.corner(v.key, 2) + double(v.z) / n * keyer.leaf),
                   float(double(v.i) / n)});
  }
  if (labels && labels_out) *labels_out = voxel_labels(cloud, keyer, table, slots, *labels);
  return out;
}

}  // namespace segmatch
