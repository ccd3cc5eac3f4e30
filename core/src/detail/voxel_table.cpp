// The crop's output order (see voxel_table.h).
#include "detail/voxel_table.h"

#include <algorithm>

namespace segmatch::voxel_table {
namespace {

constexpr int kColumns = 1 << (2 * kTileShift);  // voxel columns per tile, index (x & 15) << 4 | (y & 15)

// One tile's voxels, sorted by column then z, appended to scratch->points (and labels); the
// 17 offsets of its x columns go to scratch->lx_begin. Each voxel's point is computed while
// the table is read in slot order (sequentially); only the points are then sorted.
void append_tile_sorted(const KeptTile& tile, int64_t centre_z, double leaf, uint32_t min_points, bool with_labels,
                        EmitScratch* sc) {
  const VoxelTable& table = *tile.table;
  uint32_t start[kColumns + 1] = {};
  // Kept slots first, branch-free (the table is 25-70 % used: a branch per slot mispredicts).
  // Empty slots have n = 0.
  const uint32_t need = std::max<uint32_t>(min_points, 1);
  sc->kept_slots.resize(table.capacity());
  size_t kept = 0;
  for (size_t s = 0; s < table.capacity(); ++s) {
    sc->kept_slots[kept] = static_cast<uint32_t>(s);
    kept += table.head(s).n >= need;
  }
  sc->entries.clear();
  const int64_t x0 = tile.x * (int64_t{1} << kTileShift), y0 = tile.y * (int64_t{1} << kTileShift);
  for (size_t k = 0; k < kept; ++k) {
    const uint32_t slot = sc->kept_slots[k];
    const Head& h = table.head(slot);
    const Sums& v = table.sums(slot);
    const double n = h.n;
    const int64_t c[3] = {x0 + key_lx(h.key), y0 + key_ly(h.key), unwrap_z(h.key, centre_z)};
    double p[3];
    for (int a = 0; a < 3; ++a) p[a] = (double(c[a]) + double(v.s[a]) / kFracScale / n) * leaf;
    const uint32_t col = key_column(h.key);
    sc->entries.push_back({{float(p[0]), float(p[1]), float(p[2]), float(v.i / n)},
                           static_cast<int32_t>(c[2] - centre_z),
                           col,
                           with_labels ? table.majority(slot) : 0u});
    ++start[col + 1];
  }
  for (int c = 0; c < kColumns; ++c) start[c + 1] += start[c];
  sc->sorted.resize(sc->entries.size());
  uint32_t fill[kColumns];
  std::copy(start, start + kColumns, fill);
  for (const EmitScratch::Entry& e : sc->entries) sc->sorted[fill[e.col]++] = e;
  for (int c = 0; c < kColumns; ++c) {  // a column holds a few voxels: insertion sort by z
    for (uint32_t i = start[c] + 1; i < start[c + 1]; ++i) {
      const EmitScratch::Entry e = sc->sorted[i];
      uint32_t j = i;
      for (; j > start[c] && sc->sorted[j - 1].z > e.z; --j) sc->sorted[j] = sc->sorted[j - 1];
      sc->sorted[j] = e;
    }
  }
  const uint32_t base = static_cast<uint32_t>(sc->points.size());
  for (int lx = 0; lx <= (1 << kTileShift); ++lx) sc->lx_begin.push_back(base + start[lx << kTileShift]);
  for (const EmitScratch::Entry& e : sc->sorted) {
    sc->points.push_back(e.point);
    if (with_labels) sc->labels.push_back(e.label);
  }
}

}  // namespace

PointCloud emit_in_key_order(std::vector<KeptTile>& tiles, int64_t centre_z, double leaf, uint32_t min_points,
                             std::vector<uint32_t>* labels_out, EmitScratch* sc) {
  std::sort(tiles.begin(), tiles.end(),
            [](const KeptTile& a, const KeptTile& b) { return a.x != b.x ? a.x < b.x : a.y < b.y; });
  sc->points.clear();
  sc->labels.clear();
  sc->lx_begin.clear();
  for (const KeptTile& t : tiles) append_tile_sorted(t, centre_z, leaf, min_points, labels_out != nullptr, sc);

  // Key order: x = tile x * 16 + lx, so a strip of tiles sharing x gives its voxels lx by lx,
  // each lx tile by tile (y ascending), each tile's range already in (y, z) order.
  constexpr size_t kStride = (1 << kTileShift) + 1;
  PointCloud out;
  out.reserve(sc->points.size());
  if (labels_out) {
    labels_out->clear();
    labels_out->reserve(sc->points.size());
  }
  for (size_t i = 0; i < tiles.size();) {
    size_t j = i;
    while (j < tiles.size() && tiles[j].x == tiles[i].x) ++j;
    for (size_t lx = 0; lx < (1 << kTileShift); ++lx) {
      for (size_t k = i; k < j; ++k) {
        const uint32_t b = sc->lx_begin[kStride * k + lx], e = sc->lx_begin[kStride * k + lx + 1];
        out.insert(out.end(), sc->points.begin() + b, sc->points.begin() + e);
        if (labels_out) labels_out->insert(labels_out->end(), sc->labels.begin() + b, sc->labels.begin() + e);
      }
    }
    i = j;
  }
  return out;
}

}  // namespace segmatch::voxel_table
