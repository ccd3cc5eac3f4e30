// Segment matching (paper III-D): pair features, L2 baseline, random forest.
#include "segmatch/core/matching/matcher.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/core/matching/retrieval.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace segmatch {
namespace {

Segment random_segment(Rng& rng, uint64_t id) {
  Segment s;
  s.id = id;
  for (auto& f : s.eigen) f = static_cast<float>(rng.uniform());
  for (auto& b : s.esf) b = static_cast<float>(rng.uniform() * rng.uniform());
  s.has_eigen = s.has_esf = true;
  return s;
}

// A second observation of the same object: near-identical descriptors.
Segment observe(const Segment& s, Rng& rng, uint64_t id) {
  Segment o = s;
  o.id = id;
  for (auto& f : o.eigen) f += static_cast<float>(rng.normal(0.0, 0.01));
  for (auto& b : o.esf) b = std::max(0.f, b + static_cast<float>(rng.normal(0.0, 0.005)));
  return o;
}

struct PairSet {
  Segments a, b;  // a[i] and b[i] observe the same object
};

PairSet make_objects(int n, uint64_t seed) {
  Rng rng(seed);
  PairSet p;
  for (int i = 0; i < n; ++i) {
    p.a.push_back(random_segment(rng, i));
    p.b.push_back(observe(p.a.back(), rng, 1000 + i));
  }
  return p;
}

RandomForestMatcher train_forest(const PairSet& objects, bool use_shapes) {
  std::vector<std::pair<const Segment*, const Segment*>> pairs;
  std::vector<bool> same;
  const int n = static_cast<int>(objects.a.size());
  for (int i = 0; i < n; ++i) {
    pairs.emplace_back(&objects.a[i], &objects.b[i]);
    same.push_back(true);
    for (int j = 1; j <= 5; ++j) {  // 1:5 negatives
      pairs.emplace_back(&objects.a[i], &objects.b[(i + j * 7) % n]);
      same.push_back(false);
    }
  }
  MatcherConfig config;
  config.use_shapes = use_shapes;
  RandomForestMatcher rf(config);
  rf.train(pairs, same);
  return rf;
}

TEST(MatcherTest, PairFeaturesLayout) {
  Rng rng(1);
  Segment q = random_segment(rng, 1), t = random_segment(rng, 2);
  const auto f21 = pair_features(q, t, false);
  ASSERT_EQ(f21.size(), 21u);
  EXPECT_EQ(pair_feature_count(false), 21);
  EXPECT_EQ(pair_feature_count(true), 31);
  for (int d = 0; d < 7; ++d) {
    EXPECT_FLOAT_EQ(f21[d], std::abs(q.eigen[d] - t.eigen[d]));
    EXPECT_FLOAT_EQ(f21[7 + d], q.eigen[d]);
    EXPECT_FLOAT_EQ(f21[14 + d], t.eigen[d]);
  }
  const auto f31 = pair_features(q, t, true);
  ASSERT_EQ(f31.size(), 31u);
  for (int d = 0; d < 21; ++d) EXPECT_FLOAT_EQ(f31[d], f21[d]);
  for (int h = 21; h < 31; ++h) {
    EXPECT_GT(f31[h], 0.f);
    EXPECT_LT(f31[h], 1.f);
  }
  // Identical histograms intersect to 1 (after per-histogram normalisation), disjoint to 0.
  const auto self = pair_features(q, q, true);
  for (int h = 21; h < 31; ++h) EXPECT_NEAR(self[h], 1.f, 1e-5f);
  Segment a = q, b = q;
  a.esf.fill(0.f);
  b.esf.fill(0.f);
  for (int h = 0; h < 10; ++h) {
    a.esf[h * 64 + 3] = 5.f;
    b.esf[h * 64 + 40] = 2.f;
  }
  const auto disjoint = pair_features(a, b, true);
  for (int h = 21; h < 31; ++h) EXPECT_FLOAT_EQ(disjoint[h], 0.f);
  Segment no_esf = q;
  no_esf.has_esf = false;
  EXPECT_THROW(pair_features(no_esf, t, true), std::invalid_argument);
  EXPECT_NO_THROW(pair_features(no_esf, t, false));
}

TEST(MatcherTest, L2FilterKeepsExactlyThoseBelowThreshold) {
  Rng rng(2);
  Segments queries, targets;
  for (int i = 0; i < 30; ++i) queries.push_back(random_segment(rng, i));
  for (int i = 0; i < 40; ++i) targets.push_back(random_segment(rng, 100 + i));
  Matches candidates;
  for (int q = 0; q < 30; ++q)
    for (int t = 0; t < 40; ++t) candidates.push_back({q, t, 0.f});
  MatcherConfig config;
  config.type = MatcherType::kL2;
  config.l2_threshold = 1.5f;
  const Matches kept = filter_matches(queries, targets, candidates, config, nullptr);
  const FeatureScaling s = FeatureScaling::fit(targets);
  std::set<std::pair<int, int>> want, got;
  for (const auto& c : candidates)
    if (s.distance(queries[c.query].eigen, targets[c.target].eigen) < 1.5f) want.insert({c.query, c.target});
  for (const auto& m : kept) {
    got.insert({m.query, m.target});
    const float d = s.distance(queries[m.query].eigen, targets[m.target].eigen);
    EXPECT_NEAR(m.score, 1.f / (1.f + d), 1e-6f);
  }
  EXPECT_FALSE(want.empty());
  EXPECT_LT(want.size(), candidates.size());
  EXPECT_EQ(got, want);
}

TEST(MatcherTest, RandomForestClassifiesHeldOutPairs) {
  for (bool shapes : {false, true}) {
    const RandomForestMatcher rf = train_forest(make_objects(300, 3), shapes);
    ASSERT_TRUE(rf.trained());
    const PairSet held_out = make_objects(100, 4);
    int correct = 0, total = 0;
    for (int i = 0; i < 100; ++i) {
      correct += rf.probability(held_out.a[i], held_out.b[i]) >= 0.5f;
      correct += rf.probability(held_out.a[i], held_out.b[(i + 13) % 100]) < 0.5f;
      total += 2;
    }
    EXPECT_GE(static_cast<double>(correct) / total, 0.95) << "use_shapes=" << shapes;
    // The flattened forest votes exactly like OpenCV's RTrees::getVotes.
    std::vector<float> rows;
    for (int i = 0; i < 100; ++i)
      for (int j : {i, (i + 1) % 100, (i + 50) % 100}) {
        const auto f = pair_features(held_out.a[i], held_out.b[j], shapes);
        rows.insert(rows.end(), f.begin(), f.end());
      }
    EXPECT_EQ(rf.probabilities(rows), rf.opencv_probabilities(rows));
    // The early-exit walk is exact wherever the probability reaches its floor, and says
    // "below" (-1) everywhere else, for any floor.
    const std::vector<float> all = rf.probabilities(rows);
    std::vector<float> at_least(all.size());
    for (float floor : {0.f, 0.3f, 0.5f, 0.72f, 0.81f, 1.f}) {
      rf.probabilities_at_least(rows.data(), all.size(), floor, at_least.data());
      for (size_t r = 0; r < all.size(); ++r) {
        if (all[r] >= floor)
          EXPECT_EQ(at_least[r], all[r]) << "row " << r << " floor " << floor;
        else
          EXPECT_EQ(at_least[r], -1.f) << "row " << r << " floor " << floor;
      }
    }

    // Through filter_matches: true pairs pass the paper's threshold, few wrong ones do.
    MatcherConfig config = rf.config();
    config.rf_threshold = shapes ? 0.72f : 0.81f;
    Matches candidates;
    for (int i = 0; i < 100; ++i)
      for (int j = 0; j < 100; ++j) candidates.push_back({i, j, 0.f});
    const Matches kept = filter_matches(held_out.a, held_out.b, candidates, config, &rf);
    int true_kept = 0;
    for (const auto& m : kept) {
      true_kept += m.query == m.target;
      EXPECT_GE(m.score, config.rf_threshold);
    }
    EXPECT_GE(true_kept, 90);
    EXPECT_LE(static_cast<int>(kept.size()) - true_kept, 100);  // <1% of 9900 negatives
  }
}

TEST(MatcherTest, TrainNeedsBothClasses) {
  const PairSet objects = make_objects(5, 5);
  RandomForestMatcher rf;
  std::vector<std::pair<const Segment*, const Segment*>> pairs = {{&objects.a[0], &objects.b[0]},
                                                                  {&objects.a[1], &objects.b[1]}};
  EXPECT_THROW(rf.train(pairs, {true, true}), std::invalid_argument);
  EXPECT_THROW(rf.train(pairs, {false, false}), std::invalid_argument);
  EXPECT_THROW(rf.train(pairs, {true}), std::invalid_argument);
  EXPECT_FALSE(rf.trained());
  EXPECT_THROW(rf.probability(objects.a[0], objects.b[0]), std::logic_error);
  MatcherConfig config;
  EXPECT_THROW(filter_matches(objects.a, objects.b, {{0, 0, 0.f}}, config, &rf), std::invalid_argument);
  EXPECT_THROW(filter_matches(objects.a, objects.b, {{0, 0, 0.f}}, config, nullptr), std::invalid_argument);
}

TEST(MatcherTest, SaveLoadRoundTripGivesIdenticalProbabilities) {
  const RandomForestMatcher rf = train_forest(make_objects(200, 6), true);
  const std::string bytes = rf.save();
  const RandomForestMatcher loaded = RandomForestMatcher::load(bytes);
  EXPECT_TRUE(loaded.trained());
  EXPECT_TRUE(loaded.config().use_shapes);
  EXPECT_EQ(loaded.config().rf_trees, 25);
  const PairSet test = make_objects(50, 7);
  for (int i = 0; i < 50; ++i)
    for (int j : {i, (i + 3) % 50}) {
      EXPECT_EQ(rf.probability(test.a[i], test.b[j]), loaded.probability(test.a[i], test.b[j]));
    }
  EXPECT_EQ(loaded.save(), bytes);
  // Eigen-only model keeps its flag and refuses a shapes configuration.
  const RandomForestMatcher eigen_only = RandomForestMatcher::load(train_forest(make_objects(50, 8), false).save());
  EXPECT_FALSE(eigen_only.config().use_shapes);
  MatcherConfig shapes_config;
  EXPECT_THROW(filter_matches(test.a, test.b, {{0, 0, 0.f}}, shapes_config, &eigen_only), std::invalid_argument);
}

TEST(MatcherTest, LoadGarbageThrowsWithMessage) {
  auto expect_load_error = [](const std::string& bytes, const std::string& fragment) {
    try {
      RandomForestMatcher::load(bytes);
      ADD_FAILURE() << "no exception for: " << bytes.substr(0, 40);
    } catch (const std::runtime_error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("RandomForestMatcher::load"), std::string::npos) << msg;
      EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
    }
  };
  expect_load_error("", "empty");
  expect_load_error("this is not a model \x01\x02\xff", "");
  expect_load_error("%YAML:1.0\n---\nfoo: 3\n", "format");
  std::string bytes = train_forest(make_objects(30, 9), false).save();
  const size_t at = bytes.find("version: 1");
  ASSERT_NE(at, std::string::npos);
  bytes.replace(at, 10, "version: 7");
  expect_load_error(bytes, "version 7");
}

TEST(MatcherTest, ConfigValidation) {
  MatcherConfig c;
  EXPECT_NO_THROW(c.validate());
  c.rf_threshold = 1.5f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = MatcherConfig{};
  c.rf_trees = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = MatcherConfig{};
  c.l2_threshold = -1.f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
