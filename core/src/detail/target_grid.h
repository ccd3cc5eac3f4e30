// The refinement's nearest-neighbour structure (refine.cpp): target points bucketed in cubic
// cells, exact nearest and k nearest within a radius. Private to the core; its own header so
// that tests/core/target_grid_test.cpp can check it against brute force.
#pragma once

#include "detail/seg_grid.h"
#include "segmatch/core/common/types.h"
#include "segmatch/core/detail/simd.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>
#include <vector>

namespace segmatch {
namespace detail {

// Target points bucketed in cubic cells, stored in cell order as separate coordinate arrays
// (the scans over a cell's points are the inner loops of the refinement). The cells are those
// of CellGrid::build (sorted by key, points in input order), built here without its
// per-point cell index, which nothing here reads.
class TargetGrid {
 public:
  TargetGrid(const PointCloud& target, float cell_m) : cell_(cell_m) {
    frame_ = GridFrame::fit(target, cell_m, false, "RefineConfig.max_correspondence_m");
    std::vector<uint64_t> keys, cell_key;
    std::vector<uint32_t> order;
    keys.reserve(target.size()), order.reserve(target.size());
    for (size_t i = 0; i < target.size(); ++i) {
      if (!is_finite(target[i])) continue;
      keys.push_back(frame_.fast_key(target[i]));
      order.push_back(static_cast<uint32_t>(i));
    }
    radix_sort(keys, order, frame_.total_bits);
    for (size_t i = 0; i < keys.size(); ++i) {
      if (i > 0 && keys[i] == keys[i - 1]) continue;
      cell_key.push_back(keys[i]);
      begin_.push_back(static_cast<uint32_t>(i));
    }
    begin_.push_back(static_cast<uint32_t>(keys.size()));
    // Occupancy filter: one bit per hashed cell key, ~8 bits per occupied cell (12 % false
    // positives). Early ICP iterations probe many empty cells around points that are still
    // decimetres off the surface; the bit spares most of them a hash-map probe.
    while ((size_t{1} << filter_bits_) < 8 * cell_key.size()) ++filter_bits_;
    filter_.assign((size_t{1} << filter_bits_) / 64 + 1, 0);
    lookup_.reserve(cell_key.size());
    for (size_t c = 0; c < cell_key.size(); ++c) {
      lookup_.insert(cell_key[c], uint32_t(c));
      const uint64_t b = filter_bit(cell_key[c]);
      filter_[b >> 6] |= uint64_t{1} << (b & 63);
    }
    for (std::vector<float>* v : {&x_, &y_, &z_}) v->resize(order.size());
    for (size_t k = 0; k < order.size(); ++k) {
      x_[k] = target[order[k]].x, y_[k] = target[order[k]].y, z_[k] = target[order[k]].z;
    }
  }
  size_t size() const { return x_.size(); }
  Eigen::Vector3f point(uint32_t k) const { return {x_[k], y_[k], z_[k]}; }

  // Nearest point within sqrt(max2) of p (a point at exactly that distance counts): its index
  // (cell order) and squared distance, or false. Ties go to the smaller index, so the result
  // does not depend on the order in which distances are compared.
  // `hint` (a point index or kMissing) seeds the bound: the previous iteration's neighbour
  // is usually still within a hair of the nearest, so few cells remain to be looked at.
  bool nearest(const Eigen::Vector3f& p, float max2, uint32_t hint, uint32_t* index, float* d2) const {
    float best = std::nextafter(max2, std::numeric_limits<float>::infinity());
    uint32_t best_k = FlatHashMap::kMissing;
    if (hint != FlatHashMap::kMissing && sq_dist(hint, p) < best) {
      best = sq_dist(hint, p);
      best_k = hint;
    }
    const auto consider = [&](float d, uint32_t k) {
      if (d < best || (d == best && k < best_k)) best = d, best_k = k;
    };
    search(
        p, max2, [&] { return best; },
        [&](uint32_t k, uint32_t e) {
          if (e - k >= 4) {  // four lanes, each keeping its first minimum (indices ascend in a lane)
            simd::F4 lane_d = sq_dist4(k, p);
            simd::I4 lane_k = simd::make(int32_t(k), int32_t(k + 1), int32_t(k + 2), int32_t(k + 3)), idx = lane_k;
            for (k += 4; k + 4 <= e; k += 4) {
              idx = idx + simd::splat(int32_t(4));
              const simd::F4 d = sq_dist4(k, p);
              lane_k = simd::select_lt(d, lane_d, idx, lane_k);
              lane_d = simd::min(d, lane_d);
            }
            float ld[4];
            int32_t lk[4];
            simd::store(ld, lane_d);
            simd::store(lk, lane_k);
            for (int l = 0; l < 4; ++l) consider(ld[l], uint32_t(lk[l]));
          }
          for (; k < e; ++k) consider(sq_dist(k, p), k);
        });
    *index = best_k;
    *d2 = best;
    return best_k != FlatHashMap::kMissing;
  }

  // Up to k (<= kMaxK) nearest points within sqrt(max2) of p, appended to `out`.
  static constexpr size_t kMaxK = 16;
  void knn(const Eigen::Vector3f& p, size_t k, float max2, std::vector<uint32_t>* out) const {
    std::pair<float, uint32_t> best[kMaxK];  // ascending; insertion sort
    size_t n = 0;
    k = std::min(k, kMaxK);
    search(
        p, max2, [&] { return n < k ? max2 : best[k - 1].first; },
        [&](uint32_t b, uint32_t e) {
          for (uint32_t j = b; j < e; ++j) {
            const float d = sq_dist(j, p);
            if (d > max2 || (n == k && !(d < best[k - 1].first))) continue;
            size_t i = n < k ? n++ : k - 1;
            for (; i > 0 && d < best[i - 1].first; --i) best[i] = best[i - 1];
            best[i] = {d, j};
          }
        });
    for (size_t i = 0; i < n; ++i) out->push_back(best[i].second);
  }

  // Every point within sqrt(r2) of p, appended to `out` (cell by cell).
  void within(const Eigen::Vector3f& p, float r2, std::vector<uint32_t>* out) const {
    search(
        p, r2, [r2] { return r2; },
        [&](uint32_t b, uint32_t e) {
          for (uint32_t k = b; k < e; ++k)
            if (sq_dist(k, p) <= r2) out->push_back(k);
        });
  }

  // The squared distance every query here compares (this order of operations, these bits).
  float sq_dist(uint32_t k, const Eigen::Vector3f& p) const {
    const float dx = x_[k] - p.x(), dy = y_[k] - p.y(), dz = z_[k] - p.z();
    return dx * dx + dy * dy + dz * dz;
  }

 private:
  // sq_dist of points k..k+3: the same operations in the same order, so the same bits.
  simd::F4 sq_dist4(uint32_t k, const Eigen::Vector3f& p) const {
    const simd::F4 dx = simd::load(&x_[k]) - simd::splat(p.x());
    const simd::F4 dy = simd::load(&y_[k]) - simd::splat(p.y());
    const simd::F4 dz = simd::load(&z_[k]) - simd::splat(p.z());
    return (dx * dx + dy * dy) + dz * dz;
  }

  // Calls scan(begin, end) with the point range of every cell whose box is within
  // sqrt(bound2()) of p (bound2() may shrink meanwhile; it starts at most at max2). The own
  // cell goes first, as its points usually settle the bound; then shells of cells whose
  // distance lies in (previous reach, reach], the reach doubling until it covers the bound.
  template <typename Bound, typename Scan>
  void search(const Eigen::Vector3f& p, float max2, Bound&& bound2, Scan&& scan) const {
    const GridFrame& f = frame_;
    int64_t c[3];
    float lo_gap[3], hi_gap[3];  // distance from p to the low / high face of its cell
    for (int a = 0; a < 3; ++a) {
      const double q = double(p[a]) / f.cell_m;
      if (!(std::abs(q) < 1e15)) return;  // far outside any grid
      const double fl = std::floor(q);
      c[a] = static_cast<int64_t>(fl) - f.base[a];
      lo_gap[a] = static_cast<float>((q - fl) * f.cell_m);
      hi_gap[a] = cell_ - lo_gap[a];
    }
    scan_cell(c[0], c[1], c[2], scan);
    // Every other cell lies at least one face gap away (float sums of non-negative terms are
    // no smaller than any term), so the loop below would skip them all.
    float face2 = cell_ * cell_;
    for (int a = 0; a < 3; ++a) face2 = std::min({face2, lo_gap[a] * lo_gap[a], hi_gap[a] * hi_gap[a]});
    if (bound2() < face2) return;
    float prev2 = -1.f;
    for (float reach = cell_;; reach *= 2.f) {
      const float r2 = std::min(reach * reach, max2);
      int64_t lo[3], hi[3];  // offsets per axis whose slab is within the reach
      for (int a = 0; a < 3; ++a) {
        lo[a] = reach >= lo_gap[a] ? 1 + static_cast<int64_t>((reach - lo_gap[a]) / cell_) : 0;
        hi[a] = reach >= hi_gap[a] ? 1 + static_cast<int64_t>((reach - hi_gap[a]) / cell_) : 0;
      }
      for (int64_t dx = -lo[0]; dx <= hi[0]; ++dx) {
        const float gx = gap(lo_gap[0], hi_gap[0], dx);
        for (int64_t dy = -lo[1]; dy <= hi[1]; ++dy) {
          const float gxy = gx + gap(lo_gap[1], hi_gap[1], dy);
          if (gxy > std::min(r2, bound2())) continue;
          for (int64_t dz = -lo[2]; dz <= hi[2]; ++dz) {
            const float g = gxy + gap(lo_gap[2], hi_gap[2], dz);
            if ((dx | dy | dz) == 0 || g <= prev2 || g > std::min(r2, bound2())) continue;
            scan_cell(c[0] + dx, c[1] + dy, c[2] + dz, scan);
          }
        }
      }
      if (bound2() <= r2 || r2 >= max2) return;
      prev2 = r2;
    }
  }

  uint64_t filter_bit(uint64_t key) const { return (key * 0x9E3779B97F4A7C15ull) >> (64 - filter_bits_); }

  template <typename Scan>
  void scan_cell(int64_t x, int64_t y, int64_t z, Scan& scan) const {
    if (!frame_.inside(x, y, z)) return;
    const uint64_t key = frame_.pack(x, y, z), b = filter_bit(key);
    if (!((filter_[b >> 6] >> (b & 63)) & 1)) return;
    const uint32_t cell = lookup_.find(key);
    if (cell != FlatHashMap::kMissing) scan(begin_[cell], begin_[cell + 1]);
  }

  // Squared distance along one axis from p to the cell `d` cells away.
  float gap(float lo, float hi, int64_t d) const {
    const float g = d < 0 ? lo + float(-d - 1) * cell_ : d > 0 ? hi + float(d - 1) * cell_ : 0.f;
    return g * g;
  }

  GridFrame frame_;
  FlatHashMap lookup_;           // cell key -> cell index
  std::vector<uint32_t> begin_;  // cell c holds points begin_[c] .. begin_[c + 1] - 1
  float cell_;
  int filter_bits_ = 6;
  std::vector<uint64_t> filter_;
  std::vector<float> x_, y_, z_;
};

// TargetGrid::nearest for points that move a little between calls: the refinement's source
// points, iteration after iteration, move by millimetres once the estimate settles. A point
// that has begun to settle keeps the target points within r + 2 * margin_m of where it was
// last searched on the grid (its anchor; r its nearest distance there, or the bound when it had
// none). While it stays within margin_m of its anchor, its nearest point within the bound is
// among them (triangle inequality), and those few are scanned instead of the grid's cells. The
// answers are TargetGrid::nearest's exactly: the same distances, the same tie rule.
class NearestCache {
 public:
  NearestCache(const TargetGrid& grid, size_t points, float max_m, float margin_m)
      : grid_(grid),
        max2_(max_m * max_m),
        max_m_(max_m),
        margin_m_(margin_m),
        margin2_(margin_m * margin_m),
        entries_(points) {}

  // The nearest target point within max_m of p, for point i: as TargetGrid::nearest.
  bool nearest(size_t i, const Eigen::Vector3f& p, uint32_t* index, float* d2) {
    Entry& e = entries_[i];
    if (e.anchored && (p - e.anchor).squaredNorm() <= margin2_) {
      float best = std::nextafter(max2_, std::numeric_limits<float>::infinity());
      uint32_t best_k = FlatHashMap::kMissing;
      for (uint32_t j = e.begin; j < e.end; ++j) {
        const uint32_t k = pool_[j];
        const float d = grid_.sq_dist(k, p);
        if (d < best || (d == best && k < best_k)) best = d, best_k = k;
      }
      *index = e.last = best_k;
      *d2 = best;
      return best_k != FlatHashMap::kMissing;
    }
    const bool found = grid_.nearest(p, max2_, e.last, index, d2);
    e.last = found ? *index : FlatHashMap::kMissing;
    // Gathering costs a few nearest searches: only for a point that has begun to settle (moved
    // at most half the margin since its last call), not while the estimate still travels.
    const bool settling = e.called && (p - e.previous).squaredNorm() <= 0.25f * margin2_;
    e.previous = p;
    e.called = true;
    e.anchored = false;
    if (!settling) return found;
    // 1 mm over the bound absorbs the float rounding of the distances compared.
    const float reach = std::min(found ? std::sqrt(*d2) + 2.f * margin_m_ : max_m_ + margin_m_, max_m_ + margin_m_);
    e.anchor = p;
    e.anchored = true;
    e.begin = static_cast<uint32_t>(pool_.size());
    grid_.within(p, (reach + kSlackM) * (reach + kSlackM), &pool_);
    e.end = static_cast<uint32_t>(pool_.size());
    return found;
  }

 private:
  static constexpr float kSlackM = 1e-3f;
  struct Entry {
    Eigen::Vector3f anchor = Eigen::Vector3f::Zero(), previous = Eigen::Vector3f::Zero();
    uint32_t begin = 0, end = 0;  // its candidates: pool_[begin, end)
    uint32_t last = FlatHashMap::kMissing;
    bool anchored = false, called = false;
  };
  const TargetGrid& grid_;
  float max2_, max_m_, margin_m_, margin2_;
  std::vector<Entry> entries_;
  std::vector<uint32_t> pool_;
};

}  // namespace detail
}  // namespace segmatch
