// Candidate retrieval (paper III-D): exact kNN in z-scored eigen-feature space.
#include "segmatch/core/matching/retrieval.h"
#include "segmatch/core/detail/random.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <set>

namespace segmatch {
namespace {

// Features with very different scales per dimension, as real eigen features have.
Segments random_segments(int n, uint64_t seed) {
  Rng rng(seed);
  Segments out(n);
  for (int i = 0; i < n; ++i) {
    out[i].id = i;
    for (int d = 0; d < kEigenFeatureCount; ++d)
      out[i].eigen[d] = static_cast<float>(rng.uniform(-1.0, 1.0) * std::pow(10.0, d - 3) + d);
    out[i].has_eigen = true;
  }
  return out;
}

std::vector<std::pair<int, float>> brute_force(const Segments& targets, const EigenFeatures& q, int k) {
  // Population statistics of the targets, computed independently of FeatureScaling.
  std::array<double, kEigenFeatureCount> mean{}, sd{};
  for (int d = 0; d < kEigenFeatureCount; ++d) {
    for (const auto& t : targets) mean[d] += t.eigen[d];
    mean[d] /= targets.size();
    for (const auto& t : targets) sd[d] += (t.eigen[d] - mean[d]) * (t.eigen[d] - mean[d]);
    sd[d] = std::max(std::sqrt(sd[d] / targets.size()), 0.01);  // documented floor: noise
  }
  std::vector<std::pair<int, float>> all;
  for (size_t i = 0; i < targets.size(); ++i) {
    double sq = 0;
    for (int d = 0; d < kEigenFeatureCount; ++d) {
      const double diff = (q[d] - targets[i].eigen[d]) / sd[d];
      sq += diff * diff;
    }
    all.emplace_back(static_cast<int>(i), static_cast<float>(sq));
  }
  std::sort(all.begin(), all.end(), [](auto& a, auto& b) { return a.second < b.second; });
  all.resize(std::min<size_t>(all.size(), k));
  return all;
}

TEST(RetrievalTest, KnnEqualsBruteForce) {
  const Segments targets = random_segments(5000, 1);  // k < 100 uses the tree, else a scan
  const Segments queries = random_segments(20, 2);
  FeatureIndex index;
  index.build(targets);
  ASSERT_EQ(index.size(), 5000u);
  for (int k : {1, 7, 60, 200, 5000, 8000}) {
    for (const auto& q : queries) {
      const auto got = index.knn(q.eigen, k);
      const auto want = brute_force(targets, q.eigen, k);
      ASSERT_EQ(got.size(), want.size()) << "k=" << k;
      // Same distance at every rank (exact search); the index at a rank may only differ from
      // brute force where two distances tie to float precision, so check it by its distance.
      const auto everything = brute_force(targets, q.eigen, static_cast<int>(targets.size()));
      std::vector<float> dist_of(targets.size());
      for (const auto& [i, d] : everything) dist_of[i] = d;
      std::set<int> seen;
      for (size_t i = 0; i < got.size(); ++i) {
        EXPECT_NEAR(got[i].second, want[i].second, 1e-4f * (1.f + want[i].second));
        EXPECT_NEAR(dist_of[got[i].first], want[i].second, 1e-4f * (1.f + want[i].second))
            << "k=" << k << " rank " << i;
        EXPECT_TRUE(seen.insert(got[i].first).second) << "duplicate index";
      }
    }
  }
}

// The linear scan (k >= size / 50) selects then sorts; equal distances must still come out by
// ascending target index, as the k-d tree's exact search orders them.
TEST(RetrievalTest, ScanOrdersTiesByTargetIndex) {
  Segments targets = random_segments(300, 5);
  for (size_t i = 0; i < targets.size(); i += 3) targets[i].eigen = targets[0].eigen;  // 100 copies
  FeatureIndex index;
  index.build(targets);
  const auto nn = index.knn(targets[0].eigen, 150);
  ASSERT_EQ(nn.size(), 150u);
  for (size_t r = 0; r < 100; ++r) {
    EXPECT_EQ(nn[r].first, static_cast<int>(3 * r)) << "rank " << r;
    EXPECT_EQ(nn[r].second, 0.f);
  }
  for (size_t r = 100; r < nn.size(); ++r) EXPECT_GT(nn[r].second, 0.f);
}

TEST(RetrievalTest, NormalisationUsesTargetStatistics) {
  Segments targets(4);
  const float dim0[] = {90.f, 110.f, 90.f, 110.f};  // mean 100, sd 10
  for (int i = 0; i < 4; ++i) {
    targets[i].eigen.fill(0.5f);
    targets[i].eigen[0] = dim0[i];
    targets[i].eigen[1] = 0.001f * i;  // spread below the 0.01 floor: scaled by 1 / 0.01
    targets[i].has_eigen = true;
  }
  FeatureIndex index;
  index.build(targets);
  const FeatureScaling& s = index.scaling();
  EXPECT_NEAR(s.mean[0], 100.f, 1e-4f);
  EXPECT_NEAR(s.inv_std[0], 0.1f, 1e-6f);
  EXPECT_FLOAT_EQ(s.inv_std[1], 100.f);
  EXPECT_FLOAT_EQ(s.inv_std[2], 100.f);  // constant dimension: the floor, not 1 / 0
  // A query far from the targets uses the targets' scaling, not its own.
  EigenFeatures q = targets[0].eigen;
  q[0] = 120.f;  // 3 sd from target 0 (90) in dimension 0
  const auto nn = index.knn(q, 4);
  ASSERT_EQ(nn.size(), 4u);
  EXPECT_EQ(nn[0].first, 1);  // 110 with dim1 = 0.001 -> (1 + ((0.001-0)/sd1)^2)
  const float sd1 = 1.f / s.inv_std[1];
  EXPECT_NEAR(nn[0].second, 1.f + std::pow(0.001f / sd1, 2.f), 1e-3f);
}

TEST(RetrievalTest, CandidatesPerQueryNearestFirst) {
  const Segments targets = random_segments(50, 3);
  const Segments queries = random_segments(5, 4);
  FeatureIndex index;
  index.build(targets);
  RetrievalConfig config;
  config.k = 10;
  const Matches m = retrieve_candidates(queries, index, config);
  ASSERT_EQ(m.size(), 50u);
  for (size_t i = 0; i < m.size(); ++i) {
    EXPECT_EQ(m[i].query, static_cast<int>(i / 10));
    EXPECT_LE(m[i].score, 0.f);
    if (i % 10 != 0) {
      EXPECT_GE(m[i - 1].score, m[i].score);
    }
  }
  config.k = 200;  // more than there are targets: clipped
  EXPECT_EQ(retrieve_candidates(queries, index, config).size(), 5u * 50u);
}

TEST(RetrievalTest, EmptyIndexAndValidation) {
  FeatureIndex index;
  EXPECT_EQ(index.size(), 0u);
  EXPECT_TRUE(index.knn(EigenFeatures{}, 5).empty());
  index.build({});
  EXPECT_TRUE(index.knn(EigenFeatures{}, 5).empty());
  RetrievalConfig bad;
  bad.k = 0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  Segments no_features(1);
  EXPECT_THROW(index.build(no_features), std::invalid_argument);
  FeatureIndex moved = std::move(index);
  EXPECT_EQ(moved.size(), 0u);
}

}  // namespace
}  // namespace segmatch
