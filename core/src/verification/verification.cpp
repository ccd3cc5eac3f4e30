// Geometric verification on segment centroids (paper III-E, Table I: resolution 0.4 m,
// minimum cluster size 4). Consistency is pairwise: matches (a, b) agree if
// | |q_a - q_b| - |t_a - t_b| | < resolution, as in geometric consistency grouping used by the
// authors' implementation. The largest mutually consistent set (a clique) is grown greedily
// from every seed (or max_iterations seeds), then fitted with Umeyama (rigid, no scale).
#include "segmatch/core/verification/verification.h"
#include "detail/seg_grid.h"
#include "segmatch/core/detail/random.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace segmatch {

void VerificationConfig::validate() const {
  if (!(resolution_m > 0.f) || !std::isfinite(resolution_m))
    throw std::invalid_argument("VerificationConfig.resolution_m must be finite and > 0");
  if (min_inliers < 3) throw std::invalid_argument("VerificationConfig.min_inliers must be >= 3 (6DOF fit)");
  if (max_iterations <= 0) throw std::invalid_argument("VerificationConfig.max_iterations must be > 0");
  if (max_hypotheses < 1) throw std::invalid_argument("VerificationConfig.max_hypotheses must be >= 1");
  if (max_candidates < 0) throw std::invalid_argument("VerificationConfig.max_candidates must be >= 0 (0: no bound)");
  if (!(distinct_translation_m > 0.f) || !(distinct_rotation_deg > 0.f))
    throw std::invalid_argument("VerificationConfig.distinct_translation_m and distinct_rotation_deg must be > 0");
}

namespace {

using Vec3 = Eigen::Vector3d;
using Points = std::vector<Vec3, Eigen::aligned_allocator<Vec3>>;

// Consistency graph as a bit matrix (row i: bit j set if candidates i and j agree).
class Graph {
 public:
  explicit Graph(size_t n) : n_(n), words_((n + 63) / 64), bits_(n * words_, 0) {}
  void connect(size_t i, size_t j) {
    bits_[i * words_ + j / 64] |= uint64_t{1} << (j % 64);
    bits_[j * words_ + i / 64] |= uint64_t{1} << (i % 64);
  }
  size_t size() const { return n_; }
  size_t words() const { return words_; }
  const uint64_t* row(size_t i) const { return &bits_[i * words_]; }
  uint64_t* row(size_t i) { return &bits_[i * words_]; }

 private:
  size_t n_, words_;
  std::vector<uint64_t> bits_;
};

struct Fit {
  Pose3d T = Pose3d::Identity();
  std::vector<int> members;  // candidate indices, ascending
  double rmse = 0.0;
};

Pose3d umeyama_fit(const Points& q, const Points& t, const std::vector<int>& members) {
  Eigen::Matrix3Xd src(3, members.size()), dst(3, members.size());
  for (size_t k = 0; k < members.size(); ++k) {
    src.col(k) = q[members[k]];
    dst.col(k) = t[members[k]];
  }
  Pose3d T = Pose3d::Identity();
  T.matrix() = Eigen::umeyama(src, dst, /*with_scaling=*/false);
  return T;
}

// Fits the clique, drops members whose residual exceeds the resolution (pairwise consistency
// does not exclude e.g. mirror-image configurations) and refits until stable.
Fit fit_and_prune(const Points& q, const Points& t, std::vector<int> members, double resolution, size_t min_inliers) {
  Fit fit;
  for (int round = 0; round < 5 && members.size() >= min_inliers; ++round) {
    fit.T = umeyama_fit(q, t, members);
    std::vector<int> kept;
    for (int m : members)
      if ((fit.T * q[m] - t[m]).norm() < resolution) kept.push_back(m);
    if (kept.size() == members.size()) break;
    members = std::move(kept);
  }
  fit.members = members;
  std::sort(fit.members.begin(), fit.members.end());
  if (fit.members.size() < min_inliers) return fit;
  double sq = 0.0;
  for (int m : fit.members) sq += (fit.T * q[m] - t[m]).squaredNorm();
  fit.rmse = std::sqrt(sq / static_cast<double>(fit.members.size()));
  return fit;
}

// Compared where it matters, at the query's centre: far from the frame origin a small
// rotation difference moves the translation a lot without moving the place.
bool same_transform(const Pose3d& a, const Pose3d& b, const Vec3& centre, const VerificationConfig& config) {
  const double angle_deg = Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() * 180.0 / M_PI;
  return (a * centre - b * centre).norm() < config.distinct_translation_m && angle_deg < config.distinct_rotation_deg;
}

// Inserts `fit` into `kept` (sorted by size, descending, at most max_kept): a fit with the same
// transform as a kept one replaces it only if larger.
void keep_distinct(std::vector<Fit>& kept, Fit fit, size_t max_kept, const Vec3& centre,
                   const VerificationConfig& config) {
  for (size_t i = 0; i < kept.size(); ++i) {
    if (!same_transform(kept[i].T, fit.T, centre, config)) continue;
    if (fit.members.size() <= kept[i].members.size()) return;
    kept.erase(kept.begin() + static_cast<long>(i));
    break;
  }
  auto at = std::find_if(kept.begin(), kept.end(), [&](const Fit& f) { return f.members.size() < fit.members.size(); });
  kept.insert(at, std::move(fit));
  if (kept.size() > max_kept) kept.pop_back();
}

// Fills the consistency graph. Two matches can only agree if their target centroids are closer
// than the query's extent plus the resolution, so the targets are bucketed in square xy cells
// at least that wide and only pairs in neighbouring cells are tested: against a map of
// kilometres most of the O(n^2) pairs are never looked at (thousands of L2 matches made this
// loop most of a query's time). The test runs on centred float copies laid out per coordinate
// in cell order, so each row of it vectorises; centring each side on its own mean keeps float
// precision at the millimetre level for maps kilometres from their origin. The graph and the
// degrees are the same as from testing every pair.
void build_consistency(const Points& q, const Points& t, const Matches& candidates, float res, Graph& graph,
                       std::vector<int>& degree, const Deadline& deadline) {
  const size_t n = q.size();
  Vec3 q_mean = Vec3::Zero(), t_mean = Vec3::Zero();
  Vec3 q_lo = q[0], q_hi = q[0];
  for (size_t i = 0; i < n; ++i) {
    q_mean += q[i] / static_cast<double>(n), t_mean += t[i] / static_cast<double>(n);
    q_lo = q_lo.cwiseMin(q[i]), q_hi = q_hi.cwiseMax(q[i]);
  }
  // Cell side: the largest query distance (bounded by the box diagonal) plus the resolution,
  // with a margin for rounding; pairs farther apart in xy than that never agree.
  const double cell_m = (q_hi - q_lo).norm() + 2.0 * res + 1e-3;
  // Cell numbers offset to stay positive and clamped (a clamped cell only gets more pairs
  // tested), packed by pack_xy() so that cells (x, y - 1 .. y + 1) are one key range.
  auto cell = [&](double v) {
    const double c = std::floor(v / cell_m);
    return static_cast<int64_t>(std::isfinite(c) ? std::clamp(c, -1e6, 1e6) + 1048576.0 : 1048576.0);
  };
  std::vector<uint64_t> key(n);
  for (size_t i = 0; i < n; ++i) key[i] = detail::pack_xy(cell(t[i].x() - t_mean.x()), cell(t[i].y() - t_mean.y()));
  std::vector<int> order(n);  // candidates in cell order
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key[a] < key[b]; });
  std::vector<float> c[6];
  for (std::vector<float>& v : c) v.resize(n);
  std::vector<int> qi(n), ti(n);
  std::vector<uint64_t> sorted_key(n);
  for (size_t p = 0; p < n; ++p) {
    const size_t i = static_cast<size_t>(order[p]);
    for (int k = 0; k < 3; ++k) {
      c[k][p] = static_cast<float>(q[i][k] - q_mean[k]);
      c[3 + k][p] = static_cast<float>(t[i][k] - t_mean[k]);
    }
    qi[p] = candidates[i].query;
    ti[p] = candidates[i].target;
    sorted_key[p] = key[i];
  }
  const float *qx = c[0].data(), *qy = c[1].data(), *qz = c[2].data();
  const float *tx = c[3].data(), *ty = c[4].data(), *tz = c[5].data();
  std::vector<uint8_t> agree(n);
  // Tests position p against positions [b, e) (all > p), then records the agreeing pairs.
  auto test_range = [&](size_t p, size_t b, size_t e) {
    for (size_t r = b; r < e; ++r) {  // vectorised: no branch, no errno for sqrt (-fno-math-errno)
      const float ax = qx[p] - qx[r], ay = qy[p] - qy[r], az = qz[p] - qz[r];
      const float bx = tx[p] - tx[r], by = ty[p] - ty[r], bz = tz[p] - tz[r];
      const float dq = std::sqrt(ax * ax + ay * ay + az * az), dt = std::sqrt(bx * bx + by * by + bz * bz);
      agree[r] = (qi[p] != qi[r]) & (ti[p] != ti[r]) & (std::abs(dq - dt) < res);
    }
    const size_t i = static_cast<size_t>(order[p]);
    for (size_t r = b; r < e; ++r) {
      if (!agree[r]) continue;
      const size_t j = static_cast<size_t>(order[r]);
      graph.connect(i, j);
      ++degree[i];
      ++degree[j];
    }
  };
  auto lower = [&](uint64_t k) {
    return static_cast<size_t>(std::lower_bound(sorted_key.begin(), sorted_key.end(), k) - sorted_key.begin());
  };
  for (size_t cell_begin = 0; cell_begin < n;) {
    const uint64_t k = sorted_key[cell_begin];
    const size_t cell_end = lower(k + 1);
    // The three strips of neighbouring cells (x - 1, x, x + 1; y - 1 .. y + 1), each contiguous
    // in cell order; only positions after p, so each pair is tested once.
    size_t strip[3][2];
    for (int dx = -1; dx <= 1; ++dx) {
      const uint64_t base = k + (static_cast<uint64_t>(static_cast<int64_t>(dx)) << 32);
      strip[dx + 1][0] = lower(base - 1);
      strip[dx + 1][1] = lower(base + 2);
    }
    for (size_t p = cell_begin; p < cell_end; ++p) {
      if (p % 256 == 0 && deadline.passed()) return;  // the graph is incomplete: the caller gives up
      for (const auto& s : strip) test_range(p, std::max(s[0], p + 1), s[1]);
    }
    cell_begin = cell_end;
  }
}

// Greedy clique from seed s: its neighbours in growth order (rank), each joining when it agrees
// with every member so far. `mask` holds the candidates that agree with all members (the AND
// of their rows), so each test is one bit instead of one per member.
void grow_clique(const Graph& graph, int s, const std::vector<int>& rank, std::vector<int>& clique,
                 std::vector<int>& neighbours, std::vector<uint64_t>& mask) {
  const size_t words = graph.words();
  const uint64_t* row = graph.row(static_cast<size_t>(s));
  mask.assign(row, row + words);
  neighbours.clear();
  for (size_t w = 0; w < words; ++w)
    for (uint64_t bits = row[w]; bits != 0; bits &= bits - 1)
      neighbours.push_back(static_cast<int>(w * 64 + static_cast<size_t>(__builtin_ctzll(bits))));
  std::sort(neighbours.begin(), neighbours.end(), [&](int a, int b) { return rank[a] < rank[b]; });
  clique.assign(1, s);
  for (int c : neighbours) {
    if (!((mask[static_cast<size_t>(c) / 64] >> (c % 64)) & 1u)) continue;
    clique.push_back(c);
    const uint64_t* rc = graph.row(static_cast<size_t>(c));
    for (size_t w = 0; w < words; ++w) mask[w] &= rc[w];
  }
}

// The `max_count` candidates with the highest scores (ties: the earlier), in candidate order.
Matches best_scored(const Matches& candidates, size_t max_count) {
  std::vector<size_t> order(candidates.size());
  std::iota(order.begin(), order.end(), size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return candidates[a].score > candidates[b].score; });
  order.resize(max_count);
  std::sort(order.begin(), order.end());
  Matches kept;
  kept.reserve(max_count);
  for (size_t i : order) kept.push_back(candidates[i]);
  return kept;
}

// At most max_seeds of the matches in `order` (most-connected first): all of them when they
// fit; else half the budget on the best-connected, half on a random sample of the rest.
std::vector<int> choose_seeds(const std::vector<int>& order, size_t max_seeds, uint64_t seed) {
  if (order.size() <= max_seeds) return order;
  std::vector<int> seeds(order.begin(), order.begin() + max_seeds / 2);
  std::vector<int> rest(order.begin() + max_seeds / 2, order.end());
  Rng rng(seed);
  for (size_t k = 0; seeds.size() < max_seeds && k < rest.size(); ++k) {
    const size_t pick = k + rng.index(rest.size() - k);  // partial Fisher-Yates
    std::swap(rest[k], rest[pick]);
    seeds.push_back(rest[k]);
  }
  return seeds;
}

}  // namespace

VerificationResult verify_matches(const Segments& queries, const Segments& targets, const Matches& all_candidates,
                                  const VerificationConfig& config, const Deadline& deadline) {
  config.validate();
  const size_t bound = static_cast<size_t>(config.max_candidates);
  const Matches bounded = bound > 0 && all_candidates.size() > bound ? best_scored(all_candidates, bound) : Matches{};
  const Matches& candidates = bounded.empty() ? all_candidates : bounded;
  const size_t n = candidates.size();
  const size_t min_inliers = static_cast<size_t>(config.min_inliers);
  VerificationResult result;
  if (n < min_inliers) return result;

  Points q(n), t(n);
  for (size_t i = 0; i < n; ++i) {
    const Match& m = candidates[i];
    if (m.query < 0 || m.query >= static_cast<int>(queries.size()) || m.target < 0 ||
        m.target >= static_cast<int>(targets.size()))
      throw std::invalid_argument("verify_matches: candidate " + std::to_string(i) + " index out of range");
    q[i] = queries[m.query].centroid.cast<double>();
    t[i] = targets[m.target].centroid.cast<double>();
  }

  Vec3 centre = Vec3::Zero();
  for (const Vec3& p : q) centre += p / static_cast<double>(n);

  // Pairwise consistency graph; matches sharing a query or target segment conflict.
  const double res = config.resolution_m;
  Graph graph(n);
  std::vector<int> degree(n, 0);
  build_consistency(q, t, candidates, static_cast<float>(res), graph, degree, deadline);
  if (deadline.passed()) return result;

  // Seeds and growth order: most-connected first (ties by candidate order) - deterministic.
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return degree[a] > degree[b]; });
  const std::vector<int> seeds = choose_seeds(order, static_cast<size_t>(config.max_iterations), config.seed);

  // Distinct clusters, largest first. A seed already inside a kept cluster would mostly grow
  // that cluster again, so it is skipped: this bounds the work and yields diverse hypotheses.
  std::vector<Fit> kept;
  std::vector<char> in_kept(n, 0);
  const size_t max_kept = static_cast<size_t>(config.max_hypotheses);
  auto smallest_kept = [&] { return kept.size() < max_kept ? size_t{0} : kept.back().members.size(); };
  std::vector<int> rank(n), clique, neighbours;
  for (size_t k = 0; k < n; ++k) rank[order[k]] = static_cast<int>(k);
  std::vector<uint64_t> mask;
  for (int s : seeds) {
    if (deadline.passed()) return result;
    const size_t reach = static_cast<size_t>(degree[s]) + 1;
    if (in_kept[s] || reach < min_inliers || reach <= smallest_kept()) continue;
    grow_clique(graph, s, rank, clique, neighbours, mask);
    if (clique.size() < min_inliers || clique.size() <= smallest_kept()) continue;
    Fit fit = fit_and_prune(q, t, clique, res, min_inliers);
    if (fit.members.size() < min_inliers || fit.members.size() <= smallest_kept()) continue;
    keep_distinct(kept, std::move(fit), max_kept, centre, config);
    std::fill(in_kept.begin(), in_kept.end(), 0);
    for (const Fit& f : kept)
      for (int m : f.members) in_kept[m] = 1;
  }

  if (kept.empty()) return result;
  for (const Fit& f : kept) {
    PoseHypothesis h;
    h.T_target_query = f.T;
    h.inlier_rmse_m = static_cast<float>(f.rmse);
    for (int m : f.members) h.inliers.push_back(candidates[m]);
    result.hypotheses.push_back(std::move(h));
  }
  result.found = true;
  result.T_target_query = result.hypotheses.front().T_target_query;
  result.inlier_rmse_m = result.hypotheses.front().inlier_rmse_m;
  result.inliers = result.hypotheses.front().inliers;
  return result;
}

}  // namespace segmatch
