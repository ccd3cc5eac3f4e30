// Hypothesis ranking beyond the paper: distinct verified hypotheses, support of a pose, and
// labelled training pairs.
#include "segmatch/core/verification/support.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/core/matching/retrieval.h"
#include "segmatch/core/training/training.h"
#include "segmatch/core/verification/verification.h"

#include <gtest/gtest.h>

#include "support/poses.h"

namespace segmatch {
namespace {

Segment at(float x, float y, float z, uint32_t label = 0) {
  Segment s;
  s.centroid = Eigen::Vector3f(x, y, z);
  s.label = label;
  s.has_eigen = true;
  return s;
}

Pose3d shift(double x, double y) { return test::pose_at(x, y); }

TEST(CentroidIndex, NearestWithinEqualsBruteForce) {
  Rng rng(5);
  Segments segments;
  for (int i = 0; i < 500; ++i) segments.push_back(at(rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(0, 5)));
  const CentroidIndex index(segments, 1.0f);
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3f p(rng.uniform(-52, 52), rng.uniform(-52, 52), rng.uniform(-1, 6));
    int expected = -1;
    float best = 1.0f;
    for (size_t i = 0; i < segments.size(); ++i) {
      const float d = (segments[i].centroid - p).norm();
      if (d <= best) best = d, expected = static_cast<int>(i);
    }
    ASSERT_EQ(index.nearest_within(p, 1.0f), expected) << "query " << k;
  }
  EXPECT_EQ(index.nearest_within(Eigen::Vector3f(NAN, 0, 0), 1.0f), -1);
  EXPECT_EQ(index.nearest_within(Eigen::Vector3f(1e30f, 0, 0), 1.0f), -1);  // far beyond the grid's cells
  EXPECT_EQ(CentroidIndex().nearest_within(Eigen::Vector3f::Zero(), 1.0f), -1);
  EXPECT_EQ(CentroidIndex(Segments{}, 1.0f).nearest_within(Eigen::Vector3f::Zero(), 1.0f), -1);
}

// A street with a pole every 6 m and a few distinct objects (a kiosk, a bus stop, cars).
// Matching poles i -> i+1 is as consistent as the truth; only the truth also puts the other
// objects on top of each other.
struct PoleStreet {
  Segments map, query;
  Matches candidates;
};

PoleStreet pole_street() {
  PoleStreet s;
  for (int i = 0; i < 12; ++i) s.map.push_back(at(6.0f * i, 4.0f, 3.0f));
  const float others[][2] = {{3, -6}, {17, -5}, {29, 9}, {40, -7}, {52, 10}, {61, -4}, {9, 12}, {33, -12}};
  for (const auto& o : others) s.map.push_back(at(o[0], o[1], 1.0f));
  const Pose3d T_query_map = shift(-20.0, 3.0);  // the query frame is elsewhere
  for (const Segment& m : s.map) {
    Segment q = m;
    q.centroid = (T_query_map.cast<float>() * m.centroid).eval();
    s.query.push_back(q);
  }
  // True pole matches, the shifted ones (pole i -> pole i+1), and no match for the others:
  // the classifier could not tell them.
  for (int i = 0; i < 12; ++i) s.candidates.push_back({i, i, 1.f});
  for (int i = 0; i < 11; ++i) s.candidates.push_back({i, i + 1, 1.f});
  return s;
}

TEST(Verification, ReturnsDistinctHypothesesForRepeatedStructure) {
  const PoleStreet s = pole_street();
  const VerificationResult v = verify_matches(s.query, s.map, s.candidates, VerificationConfig{});
  ASSERT_TRUE(v.found);
  ASSERT_GE(v.hypotheses.size(), 2u);
  // Largest first; every pair of hypotheses differs by more than the distinctness bounds.
  for (size_t a = 0; a + 1 < v.hypotheses.size(); ++a) {
    EXPECT_GE(v.hypotheses[a].inliers.size(), v.hypotheses[a + 1].inliers.size());
    for (size_t b = a + 1; b < v.hypotheses.size(); ++b)
      EXPECT_GT((v.hypotheses[a].T_target_query.translation() - v.hypotheses[b].T_target_query.translation()).norm(),
                1.0);
  }
  EXPECT_TRUE(v.T_target_query.isApprox(v.hypotheses.front().T_target_query));
}

TEST(Support, RanksTheTruePoseAboveAShiftedCopyOfTheStreet) {
  const PoleStreet s = pole_street();
  const CentroidIndex index(s.map, 1.0f);
  const Pose3d T_map_query = shift(20.0, -3.0);
  const Support truth = support_of(s.query, index, T_map_query, 1.0f);
  const Support shifted = support_of(s.query, index, shift(26.0, -3.0), 1.0f);
  EXPECT_EQ(truth.count(), s.query.size());  // every segment lands on its own
  EXPECT_EQ(shifted.count(), 11u);           // only the poles line up
  for (const Match& m : truth.pairs) EXPECT_EQ(m.query, m.target);
  // And among the verified hypotheses, the one with the most support is the truth.
  const VerificationResult v = verify_matches(s.query, s.map, s.candidates, VerificationConfig{});
  size_t best = 0, best_support = 0;
  for (size_t h = 0; h < v.hypotheses.size(); ++h) {
    const size_t n = support_of(s.query, index, v.hypotheses[h].T_target_query, 1.0f).count();
    if (n > best_support) best_support = n, best = h;
  }
  EXPECT_LT((v.hypotheses[best].T_target_query.translation() - T_map_query.translation()).norm(), 0.01);
}

TEST(TrainingPairs, PositivesAreTheSameInstanceNearbyNegativesOtherInstances) {
  auto label = [](uint16_t instance) { return (static_cast<uint32_t>(instance) << 16) | 10u; };
  Segments queries{at(0, 0, 0, label(5))};
  Segments targets{at(0.5f, 0, 0, label(5)),   // same tree, another view: positive
                   at(12.0f, 0, 0, label(5)),  // same building, another part: left out
                   at(3.0f, 0, 0, label(6)),   // another object: negative
                   at(1.0f, 1, 0, 10u)};       // instance 0 (unknown): no pair
  FeatureIndex index;
  index.build(targets);
  TrainingPairConfig config;
  TrainingPairs pairs = label_pairs_by_instance(queries, targets, index, config);
  EXPECT_EQ(pairs.positives, 1u);
  EXPECT_EQ(pairs.negatives, 1u);
  ASSERT_EQ(pairs.pairs.size(), 2u);
  for (size_t i = 0; i < pairs.pairs.size(); ++i) EXPECT_EQ(pairs.same_object[i], pairs.pairs[i].second == &targets[0]);
  config.max_centroid_distance_m = 0.0f;  // instance only
  pairs = label_pairs_by_instance(queries, targets, index, config);
  EXPECT_EQ(pairs.positives, 2u);
  EXPECT_EQ(pairs.negatives, 1u);
}

TEST(TrainingPairs, RealDataLabelsByCentroidDistanceAndLeavesTheMiddleOut) {
  Segments queries{at(0, 0, 0, 0u), at(100, 0, 0, 0u)};
  Segments targets{at(0.4f, 0, 0, 0u),  // within 1.5 m: the same object seen again
                   at(2.5f, 0, 0, 0u),  // 1.5..4 m: a neighbouring piece or a pose error, left out
                   at(9.0f, 0, 0, 0u),  // beyond 4 m: negative
                   at(100, 1, 0, 0u)};  // the second query's positive
  FeatureIndex index;
  index.build(targets);
  TrainingPairConfig config;
  config.negatives_per_positive = 50;
  const TrainingPairs pairs = label_pairs_by_distance(queries, targets, index, config);
  EXPECT_EQ(pairs.positives, 2u);
  // Negatives: q0 with t2, t3; q1 with t0, t1, t2 (all far): 5, all kept at 1:50.
  EXPECT_EQ(pairs.negatives, 5u);
  for (size_t i = 0; i < pairs.pairs.size(); ++i) {
    const float d = (pairs.pairs[i].first->centroid - pairs.pairs[i].second->centroid).norm();
    EXPECT_EQ(pairs.same_object[i], d <= 1.5f) << "pair " << i;
    EXPECT_FALSE(d > 1.5f && d <= 4.0f) << "an ambiguous pair was labelled";
  }
  config.negatives_per_positive = 1;  // the ratio caps the negatives
  EXPECT_EQ(label_pairs_by_distance(queries, targets, index, config).negatives, 2u);
  config.min_negative_distance_m = 1.0f;
  EXPECT_THROW(label_pairs_by_distance(queries, targets, index, config), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
