// The Tracker's rules (api/tracker.h): global at start-up, the last fix as the prior with a
// radius growing with the distance driven, a global query after repeated failures or once the
// radius is too wide, and tracking resumed from the last fix after a failed global query.
#include "segmatch/api/tracker.h"

#include <gtest/gtest.h>

using namespace segmatch;
using namespace segmatch::api;

namespace {

LocalizeReply fix_at(double x) {
  LocalizeReply r;
  r.status = LocalizeStatus::kLocalized;
  r.T_map_local.translation() << x, 2.0, 0.0;
  return r;
}

LocalizeReply failure(LocalizeStatus status = LocalizeStatus::kNotLocalized) {
  LocalizeReply r;
  r.status = status;
  return r;
}

TrackerConfig config() {
  TrackerConfig c;
  c.initial_radius_m = 3.0;
  c.growth_per_m = 0.05;
  c.max_radius_m = 20.0;
  c.heading_tolerance_deg = 4.0;
  c.failures_before_global = 2;
  return c;
}

}  // namespace

TEST(Tracker, StartsGlobalThenTracksTheLastFixWithAGrowingRadius) {
  Tracker t(config());
  LocalizeRequest r;
  r.flags = kFlagVoxelized;
  EXPECT_EQ(t.prepare(r, 0.0), TrackMode::kGlobal);
  EXPECT_EQ(r.flags, kFlagVoxelized) << "a global query carries no prior";
  t.update(fix_at(100.0), 0.0);
  ASSERT_TRUE(t.has_fix());
  EXPECT_EQ(t.prepare(r, 40.0), TrackMode::kTracked);
  EXPECT_EQ(r.flags, kFlagVoxelized | kFlagHasPrior | kFlagPriorHeading);
  EXPECT_EQ(r.T_map_local_prior.translation().x(), 100.0);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 3.0 + 0.05 * 40.0);
  EXPECT_EQ(r.prior_heading_tolerance_deg, 4.0);
  t.update(fix_at(101.0), 40.0);  // a new fix resets the radius
  EXPECT_EQ(t.prepare(r, 40.0), TrackMode::kTracked);
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 3.0);
  EXPECT_EQ(r.T_map_local_prior.translation().x(), 101.0);
}

TEST(Tracker, RepeatedFailuresFallBackToAGlobalQueryThenTrackingResumes) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  EXPECT_EQ(t.prepare(r, 10.0), TrackMode::kTracked);
  t.update(failure(LocalizeStatus::kOutsidePrior), 10.0);
  EXPECT_EQ(t.prepare(r, 20.0), TrackMode::kTracked);
  t.update(failure(), 20.0);
  EXPECT_EQ(t.prepare(r, 30.0), TrackMode::kGlobal) << "two tracked failures in a row";
  t.update(failure(), 30.0);
  EXPECT_EQ(t.prepare(r, 40.0), TrackMode::kTracked) << "the global query failed too: back to the last fix";
  EXPECT_DOUBLE_EQ(r.prior_radius_m, 3.0 + 0.05 * 40.0);
}

TEST(Tracker, ARadiusGrownPastTheMaximumQueriesGlobally) {
  Tracker t(config());
  LocalizeRequest r;
  t.prepare(r, 0.0);
  t.update(fix_at(0.0), 0.0);
  EXPECT_EQ(t.prepare(r, 340.0), TrackMode::kTracked);  // 3 + 17 = 20 m
  EXPECT_EQ(t.prepare(r, 341.0), TrackMode::kGlobal);
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
}
