// Geometric verification (paper III-E) and ICP refinement.
#include "segmatch/core/verification/verification.h"
#include "segmatch/core/detail/random.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

namespace segmatch {
namespace {

constexpr double kDeg = M_PI / 180.0;

Pose3d true_pose() {
  Pose3d T = Pose3d::Identity();
  T.linear() =
      (Eigen::AngleAxisd(40 * kDeg, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(2 * kDeg, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(-3 * kDeg, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  T.translation() = Eigen::Vector3d(35.0, -22.0, 1.5);
  return T;
}

double rotation_error_deg(const Pose3d& a, const Pose3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() / kDeg;
}

struct Scene {
  Segments queries, targets;
  Matches candidates;
  std::set<std::pair<int, int>> truth;
};

// 60 target segments spread over 80 x 80 x 6 m; the first `n_true` are seen by the query
// (centroids mapped through T^-1, plus noise). Outliers pair a query with a wrong target.
Scene make_scene(int n_true, int n_outliers, double noise_m, uint64_t seed) {
  Rng rng(seed);
  Scene s;
  const Pose3d T = true_pose();
  for (int i = 0; i < 60; ++i) {
    Segment t;
    t.id = i;
    t.centroid = Eigen::Vector3f(rng.uniform(-40, 40), rng.uniform(-40, 40), rng.uniform(0, 6));
    s.targets.push_back(t);
  }
  for (int i = 0; i < 60; ++i) {  // query i observes target i (only n_true are candidates)
    Segment q;
    q.id = 100 + i;
    Eigen::Vector3d c = T.inverse() * s.targets[i].centroid.cast<double>();
    for (int d = 0; d < 3; ++d) c[d] += rng.normal(0.0, noise_m);
    q.centroid = c.cast<float>();
    s.queries.push_back(q);
  }
  for (int i = 0; i < n_true; ++i) {
    s.candidates.push_back({i, i, 1.f});
    s.truth.insert({i, i});
  }
  for (int k = 0; k < n_outliers; ++k) {
    const int q = rng.uniform_int(0, 59);
    int t = rng.uniform_int(0, 59);
    while (t == q) t = rng.uniform_int(0, 59);
    s.candidates.push_back({q, t, 1.f});
  }
  for (size_t i = s.candidates.size(); i > 1; --i)  // shuffle
    std::swap(s.candidates[i - 1], s.candidates[rng.index(i)]);
  return s;
}

std::set<std::pair<int, int>> as_set(const Matches& m) {
  std::set<std::pair<int, int>> out;
  for (const auto& x : m) out.insert({x.query, x.target});
  return out;
}

TEST(VerificationTest, RecoversTransformExactlyWithoutNoise) {
  const Scene s = make_scene(10, 23, 0.0, 1);  // 70% outliers
  const VerificationResult r = verify_matches(s.queries, s.targets, s.candidates, {});
  ASSERT_TRUE(r.found);
  EXPECT_EQ(as_set(r.inliers), s.truth);
  EXPECT_LT((r.T_target_query.translation() - true_pose().translation()).norm(), 1e-3);
  EXPECT_LT(rotation_error_deg(r.T_target_query, true_pose()), 1e-3);
  EXPECT_LT(r.inlier_rmse_m, 1e-3f);
}

TEST(VerificationTest, RecoversTransformWithNoise) {
  for (uint64_t seed : {2, 3, 4}) {
    const Scene s = make_scene(10, 23, 0.05, seed);
    const VerificationResult r = verify_matches(s.queries, s.targets, s.candidates, {});
    ASSERT_TRUE(r.found) << seed;
    EXPECT_EQ(as_set(r.inliers), s.truth) << seed;
    EXPECT_LT((r.T_target_query.translation() - true_pose().translation()).norm(), 0.1) << seed;
    EXPECT_LT(rotation_error_deg(r.T_target_query, true_pose()), 0.5) << seed;
    EXPECT_GT(r.inlier_rmse_m, 0.f);
    EXPECT_LT(r.inlier_rmse_m, 0.2f);
  }
}

TEST(VerificationTest, RefusesWithoutConsistentSet) {
  for (uint64_t seed : {5, 6, 7}) {
    const Scene s = make_scene(0, 40, 0.0, seed);
    const VerificationResult r = verify_matches(s.queries, s.targets, s.candidates, {});
    EXPECT_FALSE(r.found) << seed;
    EXPECT_TRUE(r.inliers.empty());
  }
  // Three true matches are below the minimum cluster size of 4.
  const Scene s = make_scene(3, 20, 0.0, 8);
  EXPECT_FALSE(verify_matches(s.queries, s.targets, s.candidates, {}).found);
  EXPECT_FALSE(verify_matches(s.queries, s.targets, {}, {}).found);
}

TEST(VerificationTest, DeterministicAndSeededBeyondIterationBudget) {
  const Scene s = make_scene(10, 60, 0.05, 9);
  VerificationConfig config;
  config.max_iterations = 8;  // fewer seeds than candidates: sampled with the seed
  const VerificationResult a = verify_matches(s.queries, s.targets, s.candidates, config);
  const VerificationResult b = verify_matches(s.queries, s.targets, s.candidates, config);
  ASSERT_TRUE(a.found);
  EXPECT_EQ(as_set(a.inliers), s.truth);
  EXPECT_EQ(as_set(a.inliers), as_set(b.inliers));
  EXPECT_TRUE(a.T_target_query.isApprox(b.T_target_query, 0.0));
}

// A query of 60 m radius against a map of kilometres, thousands of L2-style candidates: the
// pair test only looks at targets in neighbouring cells of about the query's size. The true
// set is planted at places all over the map, so it also straddles cell borders.
TEST(VerificationTest, FindsTheTrueSetAmongThousandsOfCandidatesOnAWideMap) {
  Rng rng(21);
  Segments queries(60), targets(3000);
  for (Segment& q : queries) {
    const double a = rng.uniform(0, 2 * M_PI), r = rng.uniform(3, 60);
    q.centroid = Eigen::Vector3f(r * std::cos(a), r * std::sin(a), rng.uniform(0, 5));
  }
  for (Segment& t : targets) t.centroid = Eigen::Vector3f(rng.uniform(0, 3000), rng.uniform(0, 900), rng.uniform(0, 5));
  for (int place = 0; place < 6; ++place) {
    Pose3d T = Pose3d::Identity();
    T.linear() = Eigen::AngleAxisd(rng.uniform(-M_PI, M_PI), Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(rng.uniform(100, 2900), rng.uniform(100, 800), 0.5);
    Segments map = targets;
    Matches candidates;
    std::set<std::pair<int, int>> truth;
    for (int i = 0; i < 8; ++i) {  // query i is map segment i
      map[i].centroid = (T * queries[i].centroid.cast<double>()).cast<float>();
      candidates.push_back({i, i, 1.f});
      truth.insert({i, i});
    }
    for (int k = 0; k < 4000; ++k) candidates.push_back({rng.uniform_int(0, 59), rng.uniform_int(8, 2999), 0.5f});
    const VerificationResult r = verify_matches(queries, map, candidates, {});
    ASSERT_TRUE(r.found) << place;
    EXPECT_EQ(as_set(r.inliers), truth) << place;
    EXPECT_LT((r.T_target_query.translation() - T.translation()).norm(), 1e-3) << place;
  }
}

// max_candidates: beyond it only the best-scored candidates are verified, which is the same as
// verifying that subset (an oracle: the subset given directly); at or under it nothing changes.
TEST(VerificationTest, BeyondMaxCandidatesTheBestScoredAreVerified) {
  Scene s = make_scene(10, 400, 0.02, 31);
  Rng rng(32);
  for (Match& m : s.candidates)
    m.score = s.truth.count({m.query, m.target}) ? 0.9f : static_cast<float>(rng.uniform(0.0, 0.8));
  VerificationConfig bounded;
  bounded.max_candidates = 60;
  const VerificationResult r = verify_matches(s.queries, s.targets, s.candidates, bounded);
  ASSERT_TRUE(r.found);
  EXPECT_EQ(as_set(r.inliers), s.truth);
  // The oracle: the 60 best by score, in candidate order (ties: the earlier first).
  std::vector<size_t> order(s.candidates.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return s.candidates[a].score > s.candidates[b].score; });
  order.resize(60);
  std::sort(order.begin(), order.end());
  Matches subset;
  for (size_t i : order) subset.push_back(s.candidates[i]);
  VerificationConfig unbounded;
  unbounded.max_candidates = 0;
  const VerificationResult oracle = verify_matches(s.queries, s.targets, subset, unbounded);
  ASSERT_EQ(r.hypotheses.size(), oracle.hypotheses.size());
  EXPECT_TRUE(r.T_target_query.isApprox(oracle.T_target_query, 0.0));
  for (size_t h = 0; h < r.hypotheses.size(); ++h)
    EXPECT_EQ(as_set(r.hypotheses[h].inliers), as_set(oracle.hypotheses[h].inliers));
  // At the bound (410 candidates, bound 410) and without one, the same answer.
  VerificationConfig at;
  at.max_candidates = static_cast<int>(s.candidates.size());
  const VerificationResult a = verify_matches(s.queries, s.targets, s.candidates, at);
  const VerificationResult b = verify_matches(s.queries, s.targets, s.candidates, unbounded);
  EXPECT_TRUE(a.T_target_query.isApprox(b.T_target_query, 0.0));
  EXPECT_EQ(as_set(a.inliers), as_set(b.inliers));
}

TEST(VerificationTest, ConfigValidation) {
  VerificationConfig c;
  EXPECT_NO_THROW(c.validate());
  c.resolution_m = 0.f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = VerificationConfig{};
  c.min_inliers = 2;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = VerificationConfig{};
  c.max_candidates = -1;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  const Scene s = make_scene(4, 0, 0.0, 10);
  Matches bad = s.candidates;
  bad[0].target = 999;
  EXPECT_THROW(verify_matches(s.queries, s.targets, bad, {}), std::invalid_argument);
}

// Structured scene: ground, two walls and two boxes, sampled uniformly on their surfaces.
PointCloud sample_scene(uint64_t seed, int per_m2) {
  Rng rng(seed);
  PointCloud cloud;
  auto face = [&](Eigen::Vector3d o, Eigen::Vector3d u, Eigen::Vector3d v) {
    const int n = static_cast<int>(u.norm() * v.norm() * per_m2);
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3d p = o + rng.uniform() * u + rng.uniform() * v;
      cloud.push_back({static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), 0.f});
    }
  };
  auto box = [&](Eigen::Vector3d lo, Eigen::Vector3d size) {
    const Eigen::Vector3d X(size.x(), 0, 0), Y(0, size.y(), 0), Z(0, 0, size.z());
    face(lo, X, Z);
    face(lo + Y, X, Z);
    face(lo, Y, Z);
    face(lo + X, Y, Z);
    face(lo + Z, X, Y);
  };
  face({-10, -10, 0}, {20, 0, 0}, {0, 20, 0});  // ground
  face({-10, 9, 0}, {20, 0, 0}, {0, 0, 4});     // wall along x
  face({9, -10, 0}, {0, 19, 0}, {0, 0, 3});     // wall along y
  box({-4, -3, 0}, {2, 1.5, 1.6});
  box({3, 2, 0}, {1, 3, 2.5});
  return cloud;
}

PointCloud transformed(const PointCloud& in, const Pose3d& T) {
  PointCloud out = in;
  for (auto& p : out) {
    const Eigen::Vector3f q = (T * p.xyz().cast<double>()).cast<float>();
    p.x = q.x();
    p.y = q.y();
    p.z = q.z();
  }
  return out;
}

Pose3d perturbation() {
  Pose3d P = Pose3d::Identity();
  P.linear() = Eigen::AngleAxisd(2 * kDeg, Eigen::Vector3d(0.3, -0.2, 1.0).normalized()).toRotationMatrix();
  P.translation() = Eigen::Vector3d(0.2, -0.2, 0.1);  // 0.3 m
  return P;
}

TEST(RefineTest, PointToPlaneCorrectsSmallPerturbation) {
  const Pose3d T = true_pose();
  const PointCloud target = transformed(sample_scene(11, 40), T);  // map frame
  const PointCloud query = sample_scene(12, 40);                   // other samples, query frame
  const Pose3d initial = T * perturbation();                       // perturbed in the query frame
  const RefineResult r = refine_alignment(query, target, initial, {});
  EXPECT_TRUE(r.converged);
  EXPECT_LT((r.T_target_query.translation() - T.translation()).norm(), 0.01);
  EXPECT_LT(rotation_error_deg(r.T_target_query, T), 0.1);
  EXPECT_GT(r.fitness, 0.95f);
  EXPECT_LT(r.rmse_m, 0.15f);
  // Deterministic.
  const RefineResult again = refine_alignment(query, target, initial, {});
  EXPECT_TRUE(again.T_target_query.isApprox(r.T_target_query, 0.0));
  EXPECT_EQ(again.iterations, r.iterations);
}

// The loop can end in its coarse phase (every 4th source point); the fitness reported must
// still count every point (it once counted the coarse subset: a quarter of the truth, and
// good poses were refused as "surfaces disagree").
TEST(RefineTest, FitnessCountsEveryPointWhenTheLoopEndsCoarse) {
  const Pose3d T = true_pose();
  const PointCloud target = transformed(sample_scene(11, 40), T);
  const PointCloud query = sample_scene(12, 40);
  ASSERT_GE(query.size(), 2000u) << "enough points for the coarse phase";
  RefineConfig one;
  one.max_iterations = 1;  // ends right after the first, coarse, step
  const RefineResult r = refine_alignment(query, target, T * perturbation(), one);
  EXPECT_EQ(r.iterations, 1);
  EXPECT_GT(r.fitness, 0.6f);
  const RefineResult full = refine_alignment(query, target, T * perturbation(), {});
  EXPECT_NEAR(r.fitness, full.fitness, 0.3f);
}

TEST(RefineTest, PointToPointOnIdenticalSamples) {
  const Pose3d T = true_pose();
  const PointCloud query = sample_scene(13, 20);
  const PointCloud target = transformed(query, T);
  RefineConfig config;
  config.point_to_plane = false;
  config.max_iterations = 100;
  const RefineResult r = refine_alignment(query, target, T * perturbation(), config);
  EXPECT_LT((r.T_target_query.translation() - T.translation()).norm(), 0.01);
  EXPECT_LT(rotation_error_deg(r.T_target_query, T), 0.1);
  EXPECT_LT(r.rmse_m, 0.01f);
}

TEST(RefineTest, EmptyInputAndValidation) {
  const Pose3d T = true_pose();
  const RefineResult r = refine_alignment({}, sample_scene(14, 5), T, {});
  EXPECT_FALSE(r.converged);
  EXPECT_TRUE(r.T_target_query.isApprox(T));
  RefineConfig c;
  c.max_correspondence_m = 0.f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = RefineConfig{};
  c.max_iterations = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
