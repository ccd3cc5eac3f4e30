// The Tracker's rules (api/tracker.h): global at start-up; the last fix as the prior, its radius
// three sigma of a prediction that grows with the distance driven; a global query after
// repeated failures or once the radius is too wide, tracking resumed from the last fix after a
// failed global query; answers outside the chi-square gate rejected, the fix dropped after
// repeated rejections.
#include "segmatch/api/tracker.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace segmatch;
using namespace segmatch::api;

namespace {

LocalizeReply fix_at(double x, double sigma_m = 0.0) {
  LocalizeReply r;
  r.status = LocalizeStatus::kLocalized;
  r.T_map_local.translation() << x, 2.0, 0.0;
  if (sigma_m > 0.0) {
    Eigen::Matrix<double, 6, 6> c = Eigen::Matrix<double, 6, 6>::Identity() * 1e-6;
    c(3, 3) = c(4, 4) = sigma_m * sigma_m;
    r.detail = ReplyDetail{};
    r.detail->estimate = ReplyDetail::Estimate{1, covariance_upper(c)};
  }
  return r;
}

LocalizeReply failure(LocalizeStatus status = LocalizeStatus::kNotLocalized) {
  LocalizeReply r;
  r.status = status;
  return r;
}

TrackerConfig config() {
  TrackerConfig c;
  c.min_radius_m = 3.0;
  c.drift_per_m = 0.02;
  c.radius_sigmas = 3.0;
  c.min_fix_sigma_m = 0.05;
  c.max_radius_m = 20.0;
  c.heading_tolerance_deg = 4.0;
  c.failures_before_global = 2;
  return c;
}

double expected_radius(double driven_m, double fix_sigma_m = 0.05) {
  return std::max(3.0, 3.0 * std::hypot(fix_sigma_m, 0.02 * driven_m));
}

}  // namespace

TEST(Tracker, StartsGlobalThenTracksTheLastFixWithAGrowingRadius) {
  Tracker t(config());
  LocalizeRequest r;
  r.flags = kFlagVoxelized;
  EXPECT_EQ(t.prepare(r, 0.0), TrackMode::kGlobal);
  EXPECT_EQ(r.flags, kFlagVoxelized) << "a global query carries no prior";
  EXPECT_EQ(t.update(fix_at(100.0), 0.0), TrackUpdate::kFix);
  ASSERT_TRUE(t.has_fix());
  EXPECT_EQ(t.prepare(r, 40.0), TrackMode::kTracked);
  EXPECT_EQ(r.flags, kFlagVoxelized | kFlagHasPrior | kFlagPriorHeading);
  EXPECT_EQ(r.T_map_local_prior.translation().x(), 100.0);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 3.0) << "the minimum radius";
  EXPECT_EQ(r.prior_heading_tolerance_deg, 4.0);
  EXPECT_EQ(t.prepare(r, 200.0), TrackMode::kTracked);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, expected_radius(200.0));
  EXPECT_NEAR(r.prior_radius_m, 12.0, 0.01);
  EXPECT_EQ(t.update(fix_at(101.0), 200.0), TrackUpdate::kFix);  // a new fix resets the radius
  EXPECT_EQ(t.prepare(r, 200.0), TrackMode::kTracked);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 3.0);
  EXPECT_EQ(r.T_map_local_prior.translation().x(), 101.0);
}

TEST(Tracker, TheFixCovarianceSetsTheStartingUncertainty) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0, 2.0), 0.0);  // a fix known to 2 m
  EXPECT_DOUBLE_EQ(t.sigma_m(0.0), 2.0);
  t.prepare(r, 0.0);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 6.0);
  EXPECT_DOUBLE_EQ(t.radius_m(100.0), expected_radius(100.0, 2.0));
}

TEST(Tracker, RepeatedFailuresFallBackToAGlobalQueryThenTrackingResumes) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  EXPECT_EQ(t.prepare(r, 10.0), TrackMode::kTracked);
  EXPECT_EQ(t.update(failure(LocalizeStatus::kOutsidePrior), 10.0), TrackUpdate::kFailure);
  EXPECT_EQ(t.prepare(r, 20.0), TrackMode::kTracked);
  t.update(failure(), 20.0);
  EXPECT_EQ(t.prepare(r, 30.0), TrackMode::kGlobal) << "two tracked failures in a row";
  t.update(failure(), 30.0);
  EXPECT_EQ(t.prepare(r, 40.0), TrackMode::kTracked) << "the global query failed too: back to the last fix";
  EXPECT_DOUBLE_EQ(r.prior_radius_m, expected_radius(40.0));
}

TEST(Tracker, ARadiusGrownPastTheMaximumQueriesGlobally) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  EXPECT_EQ(t.prepare(r, 333.0), TrackMode::kTracked);  // 3 sigma = 19.98 m
  EXPECT_EQ(t.prepare(r, 334.0), TrackMode::kGlobal);
}

// A global answer 30 m from where the tracker predicts the vehicle after 50 m (sigma 1 m) is
// not a fix; a second one in a row drops the fix (the prediction is then the suspect), and the
// next answer starts over.
TEST(Tracker, AnswersOutsideTheGateAreRejectedAndRepeatedRejectionsDropTheFix) {
  TrackerConfig c = config();
  c.failures_before_global = 5;
  Tracker t(c);
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  t.prepare(r, 50.0);
  EXPECT_EQ(t.update(fix_at(30.0), 50.0), TrackUpdate::kRejected);
  EXPECT_EQ(t.rejections(), 1);
  EXPECT_TRUE(t.has_fix());
  EXPECT_EQ(t.T_map_odom().translation().x(), 0.0) << "the fix is kept";
  EXPECT_EQ(t.update(fix_at(2.0), 50.0), TrackUpdate::kFix) << "2 m after 50 m: within the gate";
  t.prepare(r, 60.0);
  EXPECT_EQ(t.update(fix_at(40.0), 60.0), TrackUpdate::kRejected);
  EXPECT_EQ(t.update(fix_at(40.5), 60.0), TrackUpdate::kRejected);
  EXPECT_FALSE(t.has_fix()) << "two rejections in a row";
  EXPECT_EQ(t.prepare(r, 61.0), TrackMode::kGlobal);
  EXPECT_EQ(t.update(fix_at(41.0), 61.0), TrackUpdate::kFix);
  EXPECT_EQ(t.rejections(), 3);
}

// The answer's own covariance widens the gate: 1 m off right after a fix (sigma 0.05 m) is
// rejected when the answer claims 0.05 m, accepted when it claims 0.5 m.
TEST(Tracker, TheAnswersCovarianceWidensTheGate) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  t.prepare(r, 0.0);
  EXPECT_EQ(t.update(fix_at(1.0, 0.05), 0.0), TrackUpdate::kRejected);
  EXPECT_EQ(t.update(fix_at(1.0, 0.5), 0.0), TrackUpdate::kFix);
}

TEST(Tracker, BadConfigurationIsRefusedByName) {
  TrackerConfig c = config();
  c.max_radius_m = 1.0;
  try {
    Tracker t(c);
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_radius_m"), std::string::npos);
  }
  c = config();
  c.failures_before_global = 0;
  EXPECT_THROW(Tracker{c}, std::invalid_argument);
  c = config();
  c.gate_chi2 = 0.0;
  EXPECT_THROW(Tracker{c}, std::invalid_argument);
  c = config();
  c.drift_per_m = -1.0;
  EXPECT_THROW(Tracker{c}, std::invalid_argument);
}
