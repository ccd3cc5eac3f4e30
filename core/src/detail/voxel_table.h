// Voxel hash tables of the incremental voxel grid (voxel_accumulator.cpp), and the crop's
// output in voxel_filter's order. Private to the core.
#pragma once

#include <cstdint>
#include <vector>

#include "detail/seg_grid.h"
#include "segmatch/core/common/types.h"

namespace segmatch::voxel_table {

// z wraps to pack21()'s field width.
constexpr int kAxisBits = detail::kPack21Bits;
constexpr uint64_t kAxisMask = detail::kPack21Mask;
constexpr int64_t kAxisHalf = detail::kPack21Half;
constexpr int kTileShift = 4;  // a tile is 16 x 16 voxel columns (1.6 m at 0.1 m)
constexpr uint32_t kNoVote = ~uint32_t{0};
constexpr double kFracScale = 4294967296.0;  // 2^32: position inside the voxel, 32.32 fixed point

// A voxel's key inside its tile: x and y within the tile (4 bits each) and z wrapped to 21
// bits (tiles hold the voxels of one 16 x 16 column block; z is unwrapped around the crop).
static_assert(2 * kTileShift + kAxisBits < 32, "a local key never equals kEmpty");
constexpr uint32_t kEmpty = ~uint32_t{0};
inline uint32_t local_key(const int64_t v[3]) {
  constexpr uint64_t kLocal = (uint64_t{1} << kTileShift) - 1;
  return static_cast<uint32_t>((static_cast<uint64_t>(v[0]) & kLocal) << (kTileShift + kAxisBits) |
                               (static_cast<uint64_t>(v[1]) & kLocal) << kAxisBits |
                               (static_cast<uint64_t>(v[2]) & kAxisMask));
}
inline uint32_t key_column(uint32_t key) { return key >> kAxisBits; }  // (x << 4) | y in the tile
inline int64_t key_lx(uint32_t key) { return key >> (kTileShift + kAxisBits); }
inline int64_t key_ly(uint32_t key) { return (key >> kAxisBits) & ((1u << kTileShift) - 1); }

// The z congruent to the key's wrapped z nearest `centre`.
inline int64_t unwrap_z(uint32_t key, int64_t centre) {
  const uint64_t w = key & kAxisMask;
  int64_t d = static_cast<int64_t>((w - static_cast<uint64_t>(centre)) & kAxisMask);
  if (d >= kAxisHalf) d -= int64_t{1} << kAxisBits;
  return centre + d;
}

// A voxel's slot, in three arrays: the heads (key, count) are what a crop scans, the sums are
// read only for the voxels it keeps, the label votes only when labels are asked for.
struct Head {
  uint32_t key;  // kEmpty: a free slot
  uint32_t n;
  static Head free_slot() { return {kEmpty, 0}; }
  bool is_free() const { return key == kEmpty; }
};
struct Sums {
  int64_t s[3];  // sums of the fixed-point positions inside the voxel
  double i;      // intensity sum
};
struct Vote {
  uint32_t label, count, next;
};

// The heads in an OpenTable, the sums and votes in arrays beside it. A voxel whose count drops
// to 0 keeps its slot until the next rebuild, which keeps only live voxels; compact() rebuilds
// once such slots outnumber the live ones, so that a crop does not scan tables mostly dead.
class VoxelTable {
 public:
  VoxelTable() : heads_(kInitialVoxels), sums_(heads_.capacity(), Sums{}) {}
  size_t capacity() const { return heads_.capacity(); }
  size_t live() const { return live_; }
  const Head& head(size_t s) const { return heads_[s]; }
  const Sums& sums(size_t s) const { return sums_[s]; }
  void prefetch(uint32_t key) const {
    heads_.prefetch(key);
    __builtin_prefetch(&sums_[heads_.home(key)]);
  }

  // Adds (sign +1) or removes (-1) one point.
  void add(uint32_t key, const int64_t f[3], float intensity, uint32_t label, int sign) {
    bool claimed = false;
    size_t s;
    while ((s = heads_.find_or_claim(key, &claimed)) == detail::OpenTable<Head>::kNone) rebuild(live_ + 1);
    Head& h = heads_[s];
    Sums& v = sums_[s];
    if (sign > 0) {
      if (h.n++ == 0) ++live_;
      v.s[0] += f[0], v.s[1] += f[1], v.s[2] += f[2];
      v.i += intensity;
    } else {
      if (--h.n == 0) --live_;
      v.s[0] -= f[0], v.s[1] -= f[1], v.s[2] -= f[2];
      v.i -= intensity;
    }
    if (label != 0) vote(s, label, sign);
  }

  // After removals: rebuilds once dead slots (count 0) outnumber the live voxels.
  void compact() {
    if (heads_.used() - live_ > live_ && heads_.capacity() > 4 * kInitialVoxels) rebuild(live_);
  }

  // Majority non-zero label of slot s (ties: the smaller label; 0 if none), as
  // detail::majority_label.
  uint32_t majority(size_t s) const {
    if (first_vote_.empty()) return 0;
    uint32_t best = 0, best_count = 0;
    for (uint32_t u = first_vote_[s]; u != kNoVote; u = votes_[u].next) {
      const Vote& x = votes_[u];
      if (x.count > best_count || (x.count == best_count && x.count > 0 && x.label < best)) {
        best = x.label;
        best_count = x.count;
      }
    }
    return best;
  }

 private:
  static constexpr size_t kInitialVoxels = 16;

  void vote(size_t s, uint32_t label, int sign) {
    if (first_vote_.empty()) first_vote_.assign(heads_.capacity(), kNoVote);
    for (uint32_t u = first_vote_[s]; u != kNoVote; u = votes_[u].next)
      if (votes_[u].label == label) {
        votes_[u].count += sign;
        return;
      }
    // A removed point's label was voted when it was added, so only additions get here.
    votes_.push_back({label, 1u, first_vote_[s]});
    first_vote_[s] = static_cast<uint32_t>(votes_.size() - 1);
  }
  // Keeps the live voxels (and their live votes) in a table sized for `expected`.
  void rebuild(size_t expected) {
    const std::vector<Sums> old_sums = std::move(sums_);
    const std::vector<uint32_t> old_first = std::move(first_vote_);
    const std::vector<Vote> old_votes = std::move(votes_);
    sums_.clear();
    first_vote_.clear();
    votes_.clear();
    heads_.rebuild(
        expected, [](const Head& h) { return h.n != 0; },
        [&](size_t o, size_t s) {
          if (sums_.empty()) {  // the first move: the new capacity is known
            sums_.assign(heads_.capacity(), Sums{});
            if (!old_first.empty()) first_vote_.assign(heads_.capacity(), kNoVote);
          }
          sums_[s] = old_sums[o];
          if (old_first.empty()) return;
          for (uint32_t u = old_first[o]; u != kNoVote; u = old_votes[u].next) {
            if (old_votes[u].count == 0) continue;
            votes_.push_back({old_votes[u].label, old_votes[u].count, first_vote_[s]});
            first_vote_[s] = static_cast<uint32_t>(votes_.size() - 1);
          }
        });
    if (sums_.empty()) sums_.assign(heads_.capacity(), Sums{});  // nothing was live
    live_ = heads_.used();
  }

  detail::OpenTable<Head> heads_;
  std::vector<Sums> sums_;            // parallel to the heads
  std::vector<uint32_t> first_vote_;  // per slot, head of its vote list; empty until a label comes
  std::vector<Vote> votes_;
  size_t live_ = 0;
};

// A tile of 16 x 16 voxel columns (tile coordinates = voxel column >> kTileShift) whose
// voxels a crop keeps.
struct KeptTile {
  int64_t x, y;
  const VoxelTable* table;
};

// Buffers reused between crops (no page faults on every crop).
struct EmitScratch {
  struct Entry {
    Point point;
    int32_t z;       // voxel z relative to the crop centre
    uint32_t col;    // voxel column in the tile
    uint32_t label;  // majority label (0 without labels)
  };
  std::vector<uint32_t> kept_slots;
  std::vector<Entry> entries, sorted;
  std::vector<Point> points;
  std::vector<uint32_t> labels;
  std::vector<uint32_t> lx_begin;  // per kept tile, 17 offsets into points (one range per lx)
};

// The occupied voxels (>= min_points) of the kept tiles, as voxel_filter gives them: each the
// centroid of its points, in voxel key order (x, then y, then z), with majority labels if
// labels_out. Sorts tiles by (x, y), voxels inside a tile by (x, y, z), then emits each strip
// of tiles sharing x column by column: no global sort. Reorders `tiles`.
PointCloud emit_in_key_order(std::vector<KeptTile>& tiles, int64_t centre_z, double leaf, uint32_t min_points,
                             std::vector<uint32_t>* labels_out, EmitScratch* scratch);

}  // namespace segmatch::voxel_table
