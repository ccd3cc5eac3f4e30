// The private grid helpers of seg_grid.h: radix sort, flat hash map, grid frames and cell
// grids, majority labels.
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "detail/seg_grid.h"

namespace segmatch {
namespace detail {

namespace {

constexpr int kDigitBits = 11;
constexpr size_t kBuckets = size_t{1} << kDigitBits;

// One counting-sort pass on the digit at `shift` of `keys`, into `out`.
template <typename Fn>
void radix_pass(const std::vector<uint64_t>& keys, std::vector<uint64_t>& out, int shift, std::vector<uint32_t>& count,
                Fn&& moved) {
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

void sort_packed(std::vector<uint64_t>& words, int key_bits) {
  if (key_bits == 0) return;
  // All digit histograms come from one read; digits of up to 13 bits make a 25-bit key (a 60 m
  // cloud at 0.2 m) two passes.
  const int passes = (key_bits + 12) / 13, digit = (key_bits + passes - 1) / passes;
  const uint64_t mask = (uint64_t{1} << digit) - 1;
  std::vector<uint32_t> count(static_cast<size_t>(passes) << digit, 0);
  for (uint64_t w : words) {
    for (int p = 0; p < passes; ++p) {
      ++count[(static_cast<size_t>(p) << digit) + ((w >> (32 + p * digit)) & mask)];
    }
  }
  std::vector<uint64_t> tmp(words.size());
  for (int p = 0; p < passes; ++p) {
    uint32_t* c = &count[static_cast<size_t>(p) << digit];
    uint32_t sum = 0;
    for (uint64_t b = 0; b <= mask; ++b) {
      const uint32_t n = c[b];
      c[b] = sum;
      sum += n;
    }
    for (uint64_t w : words) tmp[c[(w >> (32 + p * digit)) & mask]++] = w;
    words.swap(tmp);
  }
}

void radix_sort(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits) {
  const size_t n = keys.size();
  if (key_bits <= 32) {  // pack key and value into one word: half the memory traffic
    for (size_t i = 0; i < n; ++i) keys[i] = (keys[i] << 32) | values[i];
    sort_packed(keys, key_bits);
    for (size_t i = 0; i < n; ++i) {
      values[i] = static_cast<uint32_t>(keys[i]);
      keys[i] >>= 32;
    }
    return;
  }
  std::vector<uint32_t> count(kBuckets);
  std::vector<uint64_t> tmp(n);
  std::vector<uint32_t> values_tmp(n);
  for (int shift = 0; shift < key_bits; shift += kDigitBits) {
    radix_pass(keys, tmp, shift, count, [&](size_t i, uint32_t dst) { values_tmp[dst] = values[i]; });
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

CellGrid CellGrid::build(const PointCloud& cloud, double cell_m, bool planar, const char* field, bool with_lookup) {
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

}  // namespace segmatch
