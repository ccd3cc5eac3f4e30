// P(x) (paper equation 1), true / false localization scoring and ROC curves on hand-made
// outcomes whose answers are known.
#include "segmatch/eval/metrics.h"
#include "segmatch/eval/roc.h"

#include <gtest/gtest.h>

using namespace segmatch;
using namespace segmatch::eval;

namespace {

QueryOutcome at(double odometer_m, bool correct, bool mapped = true) {
  QueryOutcome o;
  o.odometer_m = odometer_m;
  o.localized = correct;
  o.correct = correct;
  o.mapped = mapped;
  return o;
}

}  // namespace

TEST(Px, GapsBetweenTrueLocalizations) {
  // Localized at 10, 20 and 70 m of a 100 m drive that starts at 0: gaps 10, 10, 50, 30.
  const std::vector<QueryOutcome> o = {at(0, false),  at(10, true), at(20, true),
                                       at(40, false), at(70, true), at(100, false)};
  const PxCurve c = px_curve(o);
  ASSERT_EQ(c.gaps_m.size(), 4u);
  EXPECT_DOUBLE_EQ(c.total_m, 100.0);
  EXPECT_DOUBLE_EQ(c.p_of(0.0), 1.0);
  EXPECT_DOUBLE_EQ(c.p_of(10.0), 1.0);
  EXPECT_DOUBLE_EQ(c.p_of(10.5), 0.8);  // the 50 and 30 m gaps
  EXPECT_DOUBLE_EQ(c.p_of(31.0), 0.5);
  EXPECT_DOUBLE_EQ(c.p_of(51.0), 0.0);
  EXPECT_DOUBLE_EQ(c.x95_m, 50.0);  // only above the longest gap is P <= 5 %
}

TEST(Px, UnmappedStretchesDoNotCount) {
  // 0..50 m on mapped streets, 50..150 m on a street the map never saw, then localized at 160.
  const std::vector<QueryOutcome> o = {at(0, true), at(50, false), at(100, false, false), at(150, false, false),
                                       at(160, true)};
  const PxCurve c = px_curve(o);
  EXPECT_DOUBLE_EQ(c.total_m, 60.0);
  ASSERT_EQ(c.gaps_m.size(), 1u);
  EXPECT_DOUBLE_EQ(c.gaps_m[0], 60.0);
}

TEST(Px, FalseLocalizationsDoNotEndAGap) {
  std::vector<QueryOutcome> o = {at(0, true), at(10, false), at(20, true)};
  o[1].localized = true;  // localized, but wrong
  const Summary s = summarize(o);
  EXPECT_EQ(s.false_localizations, 1u);
  EXPECT_EQ(s.correct, 2u);
  ASSERT_EQ(s.px.gaps_m.size(), 1u);
  EXPECT_DOUBLE_EQ(s.px.gaps_m[0], 20.0);
}

TEST(Score, FalseBeyondOneMetreOrThreeDegrees) {
  Pose3d truth = Pose3d::Identity();
  truth.translation() << 5, 5, 0;
  QueryOutcome o;
  o.localized = true;
  Pose3d estimate = truth;
  estimate.translation().x() += 0.5;
  score(o, estimate, truth, Thresholds{});
  EXPECT_TRUE(o.correct);
  EXPECT_NEAR(o.error_m, 0.5, 1e-9);
  estimate = truth;
  estimate.rotate(Eigen::AngleAxisd(4.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  score(o, estimate, truth, Thresholds{});
  EXPECT_FALSE(o.correct);
  EXPECT_NEAR(o.error_deg, 4.0, 1e-6);
  estimate = truth;
  estimate.translation().y() += 1.5;
  score(o, estimate, truth, Thresholds{});
  EXPECT_FALSE(o.correct);
}

TEST(Roc, PerfectRandomAndOperatingPoint) {
  std::vector<ScoredPair> perfect, inverted;
  for (int i = 0; i < 10; ++i) {
    perfect.push_back({1.0 + i, true});
    perfect.push_back({-1.0 - i, false});
    inverted.push_back({-1.0 - i, true});
    inverted.push_back({1.0 + i, false});
  }
  const RocCurve p = roc_curve("perfect", perfect);
  EXPECT_NEAR(p.auc, 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(p.operating_tpr, 1.0);
  EXPECT_DOUBLE_EQ(p.operating_fpr, 0.2);  // the last point with FPR <= 0.2
  EXPECT_NEAR(roc_curve("inverted", inverted).auc, 0.0, 1e-12);
  EXPECT_THROW(roc_curve("none", {{1.0, true}}), std::invalid_argument);
}

TEST(Roc, TiesAreOnePoint) {
  // All scores equal: the curve jumps from (0, 0) straight to (1, 1), AUC 0.5.
  const RocCurve c = roc_curve("ties", {{0.5, true}, {0.5, false}, {0.5, true}, {0.5, false}});
  ASSERT_EQ(c.fpr.size(), 2u);
  EXPECT_NEAR(c.auc, 0.5, 1e-12);
}
