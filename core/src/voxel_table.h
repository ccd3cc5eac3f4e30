// Voxel hash tables of the incremental voxel grid (voxel_accumulator.cpp), and the crop's
// output in voxel_filter's order. Private to the core.
#pragma once

#include <cstdint>
#include <vector>

#include "segmatch/core/types.h"

namespace segmatch::voxel_table {

constexpr int kAxisBits = 21;
constexpr uint64_t kAxisMask = (uint64_t{1} << kAxisBits) - 1;
constexpr int64_t kAxisHalf = int64_t{1} << (kAxisBits - 1);
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
  uint32_t key;
  uint32_t n;
};
struct Sums {
  int64_t s[3];  // sums of the fixed-point positions inside the voxel
  double i;      // intensity sum
};
struct Vote {
  uint32_t label, count, next;
};

// Open addressing, linear probing, power-of-two capacity, 25..70 % used: it grows when a new
// voxel would fill it beyond 70 %. A voxel whose count drops to 0 keeps its slot until the
// next rebuild, which keeps only live voxels; compact() rebuilds once such slots outnumber
// the live ones, so that a crop does not scan tables mostly dead.
class VoxelTable {
 public:
  VoxelTable() { allocate(0); }
  size_t capacity() const { return heads_.size(); }
  size_t live() const { return live_; }
  const Head& head(size_t s) const { return heads_[s]; }
  const Sums& sums(size_t s) const { return sums_[s]; }
  size_t home(uint32_t key) const { return static_cast<size_t>((key * 0x9E3779B97F4A7C15ull) >> shift_); }
  void prefetch(uint32_t key) const {
    const size_t s = home(key);
    __builtin_prefetch(&heads_[s]);
    __builtin_prefetch(&sums_[s]);
  }

  // Adds (sign +1) or removes (-1) one point.
  void add(uint32_t key, const int64_t f[3], float intensity, uint32_t label, int sign) {
    size_t s = home(key);
    while (heads_[s].key != key) {
      if (heads_[s].key == kEmpty) {
        if (10 * (used_ + 1) > 7 * heads_.size()) {  // full: rebuild (larger), probe again
          rebuild(live_ + 1);
          s = home(key);
          continue;
        }
        heads_[s].key = key;
        ++used_;
        break;
      }
      s = (s + 1) & mask_;
    }
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
    if (used_ - live_ > live_ && heads_.size() > 64) rebuild(live_);
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
  void vote(size_t s, uint32_t label, int sign) {
    if (first_vote_.empty()) first_vote_.assign(heads_.size(), kNoVote);
    for (uint32_t u = first_vote_[s]; u != kNoVote; u = votes_[u].next)
      if (votes_[u].label == label) {
        votes_[u].count += sign;
        return;
      }
    // A removed point's label was voted when it was added, so only additions get here.
    votes_.push_back({label, 1u, first_vote_[s]});
    first_vote_[s] = static_cast<uint32_t>(votes_.size() - 1);
  }
  void allocate(size_t expected) {
    size_t capacity = 64;
    while (2 * expected > capacity) capacity <<= 1;  // <= 50 % used after (re)allocation
    heads_.assign(capacity, Head{kEmpty, 0});
    sums_.assign(capacity, Sums{{0, 0, 0}, 0.0});
    first_vote_.clear();
    votes_.clear();
    mask_ = capacity - 1;
    shift_ = 64;
    while ((size_t{1} << (64 - shift_)) < capacity) --shift_;
    used_ = live_ = 0;
  }
  void rebuild(size_t expected) {
    const std::vector<Head> old = std::move(heads_);
    const std::vector<Sums> old_sums = std::move(sums_);
    const std::vector<uint32_t> old_first = std::move(first_vote_);
    const std::vector<Vote> old_votes = std::move(votes_);
    allocate(expected);
    if (!old_first.empty()) first_vote_.assign(heads_.size(), kNoVote);
    for (size_t o = 0; o < old.size(); ++o) {
      if (old[o].key == kEmpty || old[o].n == 0) continue;
      size_t s = home(old[o].key);
      while (heads_[s].key != kEmpty) s = (s + 1) & mask_;
      heads_[s] = old[o];
      sums_[s] = old_sums[o];
      ++used_, ++live_;
      if (old_first.empty()) continue;
      for (uint32_t u = old_first[o]; u != kNoVote; u = old_votes[u].next) {
        if (old_votes[u].count == 0) continue;
        votes_.push_back({old_votes[u].label, old_votes[u].count, first_vote_[s]});
        first_vote_[s] = static_cast<uint32_t>(votes_.size() - 1);
      }
    }
  }

  std::vector<Head> heads_;
  std::vector<Sums> sums_;
  std::vector<uint32_t> first_vote_;  // per slot, head of its vote list; empty until a label comes
  std::vector<Vote> votes_;
  size_t mask_ = 0, used_ = 0, live_ = 0;
  int shift_ = 58;
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
PointCloud emit_in_key_order(std::vector<KeptTile>& tiles, int64_t centre_z, double leaf,
                             uint32_t min_points, std::vector<uint32_t>* labels_out, EmitScratch* scratch);

}  // namespace segmatch::voxel_table
