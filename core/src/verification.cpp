// Geometric verification on segment centroids (paper III-E, Table I: resolution 0.4 m,
// minimum cluster size 4). Consistency is pairwise: matches (a, b) agree if
// | |q_a - q_b| - |t_a - t_b| | < resolution, as in geometric consistency grouping used by the
// authors' implementation. The largest mutually consistent set (a clique) is grown greedily
// from every seed (or max_iterations seeds), then fitted with Umeyama (rigid, no scale).
#include "segmatch/core/verification.h"
#include "segmatch/core/random.h"

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
  if (min_inliers < 3)
    throw std::invalid_argument("VerificationConfig.min_inliers must be >= 3 (6DOF fit)");
  if (max_iterations <= 0)
    throw std::invalid_argument("VerificationConfig.max_iterations must be > 0");
  if (max_hypotheses < 1)
    throw std::invalid_argument("VerificationConfig.max_hypotheses must be >= 1");
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
  bool connected(size_t i, size_t j) const {
    return (bits_[i * words_ + j / 64] >> (j % 64)) & 1u;
  }
  size_t size() const { return n_; }

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
Fit fit_and_prune(const Points& q, const Points& t, std::vector<int> members, double resolution,
                  size_t min_inliers) {
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
  auto at = std::find_if(kept.begin(), kept.end(),
                         [&](const Fit& f) { return f.members.size() < fit.members.size(); });
  kept.insert(at, std::move(fit));
  if (kept.size() > max_kept) kept.pop_back();
}

}  // namespace

VerificationResult verify_matches(const Segments& queries, const Segments& targets,
                                  const Matches& candidates, const VerificationConfig& config) {
  config.validate();
  const size_t n = candidates.size();
  const size_t min_inliers = static_cast<size_t>(config.min_inliers);
  VerificationResult result;
  if (n < min_inliers) return result;

  Points q(n), t(n);
  for (size_t i = 0; i < n; ++i) {
    const Match& m = candidates[i];
    if (m.query < 0 || m.query >= static_cast<int>(queries.size()) || m.target < 0 ||
        m.target >= static_cast<int>(targets.size()))
      throw std::invalid_argument("verify_matches: candidate " + std::to_string(i) +
                                  " index out of range");
    q[i] = queries[m.query].centroid.cast<double>();
    t[i] = targets[m.target].centroid.cast<double>();
  }

  Vec3 centre = Vec3::Zero();
  for (const Vec3& p : q) centre += p / static_cast<double>(n);

  // Pairwise consistency graph; matches sharing a query or target segment conflict.
  const double res = config.resolution_m;
  Graph graph(n);
  std::vector<int> degree(n, 0);
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = i + 1; j < n; ++j) {
      if (candidates[i].query == candidates[j].query || candidates[i].target == candidates[j].target)
        continue;
      if (std::abs((q[i] - q[j]).norm() - (t[i] - t[j]).norm()) < res) {
        graph.connect(i, j);
        ++degree[i];
        ++degree[j];
      }
    }
  }

  // Seeds and growth order: most-connected first (ties by candidate order) - deterministic.
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return degree[a] > degree[b]; });
  std::vector<int> seeds = order;
  const size_t max_seeds = static_cast<size_t>(config.max_iterations);
  if (n > max_seeds) {
    // Half the budget on the best-connected seeds, half on a random sample of the rest.
    seeds.assign(order.begin(), order.begin() + max_seeds / 2);
    std::vector<int> rest(order.begin() + max_seeds / 2, order.end());
    Rng rng(config.seed);
    for (size_t k = 0; seeds.size() < max_seeds && k < rest.size(); ++k) {
      const size_t pick = k + rng.index(rest.size() - k);  // partial Fisher-Yates
      std::swap(rest[k], rest[pick]);
      seeds.push_back(rest[k]);
    }
  }

  // Distinct clusters, largest first. A seed already inside a kept cluster would mostly grow
  // that cluster again, so it is skipped: this bounds the work and yields diverse hypotheses.
  std::vector<Fit> kept;
  std::vector<char> in_kept(n, 0);
  const size_t max_kept = static_cast<size_t>(config.max_hypotheses);
  auto smallest_kept = [&] { return kept.size() < max_kept ? size_t{0} : kept.back().members.size(); };
  std::vector<int> clique;
  for (int s : seeds) {
    const size_t reach = static_cast<size_t>(degree[s]) + 1;
    if (in_kept[s] || reach < min_inliers || reach <= smallest_kept()) continue;
    clique.assign(1, s);
    for (int c : order) {
      if (c == s || !graph.connected(s, c)) continue;
      bool all = true;
      for (size_t k = 1; k < clique.size() && all; ++k) all = graph.connected(clique[k], c);
      if (all) clique.push_back(c);
    }
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
