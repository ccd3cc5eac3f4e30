// Tracking between fixes through the server: a wrong prior costs a few queries and
// falls back to a global one, never a false pose; after a gap in the map (queries that cannot
// localize while the vehicle drives on) tracking recovers.
#include "server_test_util.h"

#include <segmatch/api/tracker.h>

using namespace segmatch;
using namespace segmatch::testing;

namespace {

constexpr double kQuerySpacingM = 15.0;  // TestWorld: revisit local clouds every 15 m

bool accurate(const api::LocalizeReply& r, const Query& q) {
  const Pose3d T_map_sensor = r.T_map_local * q.T_local_sensor;
  return (T_map_sensor.translation() - q.T_world_sensor.translation()).norm() <= 1.0;
}

api::TrackerConfig tracker_config() {
  api::TrackerConfig c;
  c.failures_before_global = 2;
  return c;
}

}  // namespace

TEST(ServerTracking, AWrongPriorFallsBackToAGlobalQueryNeverAFalsePose) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  api::Tracker tracker(tracker_config());
  // A "fix" 60 m off, as a bad initialisation would give.
  api::LocalizeReply wrong;
  wrong.status = api::LocalizeStatus::kLocalized;
  wrong.T_map_local = w.queries().front().T_world_sensor * w.queries().front().T_local_sensor.inverse();
  wrong.T_map_local.translation() += Eigen::Vector3d(60.0, 0.0, 0.0);
  tracker.update(wrong, 0.0);
  size_t global = 0, tracked_fixes_after_global = 0, falses = 0;
  for (size_t i = 0; i < w.queries().size(); ++i) {
    const double odometer_m = kQuerySpacingM * static_cast<double>(i);
    api::LocalizeRequest request = w.queries()[i].request;
    const api::TrackMode mode = tracker.prepare(request, odometer_m);
    const api::LocalizeReply r = c.localize(request);
    tracker.update(r, odometer_m);
    global += mode == api::TrackMode::kGlobal;
    if (r.status != api::LocalizeStatus::kLocalized) continue;
    falses += !accurate(r, w.queries()[i]);
    tracked_fixes_after_global += global > 0 && mode == api::TrackMode::kTracked;
    std::printf("[track] query %zu: %s localized\n", i, api::to_string(mode));
  }
  EXPECT_EQ(falses, 0u);
  EXPECT_GE(global, 1u) << "the wrong prior must give way to a global query";
  EXPECT_GE(tracked_fixes_after_global, 1u) << "tracking resumes from the global fix";
}

TEST(ServerTracking, TrackingRecoversAfterAGapInTheMap) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  api::Tracker tracker(tracker_config());
  double odometer_m = 0.0;
  size_t i = 0, localized_before = 0;
  for (; i < w.queries().size() / 2; ++i, odometer_m += kQuerySpacingM) {
    api::LocalizeRequest request = w.queries()[i].request;
    tracker.prepare(request, odometer_m);
    const api::LocalizeReply r = c.localize(request);
    tracker.update(r, odometer_m);
    localized_before += r.status == api::LocalizeStatus::kLocalized;
  }
  ASSERT_GE(localized_before, 1u);
  // 300 m through streets the map never saw: nothing to localize against.
  for (int k = 0; k < 5; ++k, odometer_m += 60.0) {
    api::LocalizeRequest empty = w.queries()[i].request;
    empty.points.clear();
    tracker.prepare(empty, odometer_m);
    tracker.update(c.localize(empty), odometer_m);
  }
  size_t recovered_at = SIZE_MAX, falses = 0;
  for (size_t j = i; j < w.queries().size(); ++j, odometer_m += kQuerySpacingM) {
    api::LocalizeRequest request = w.queries()[j].request;
    tracker.prepare(request, odometer_m);
    const api::LocalizeReply r = c.localize(request);
    tracker.update(r, odometer_m);
    if (r.status != api::LocalizeStatus::kLocalized) continue;
    falses += !accurate(r, w.queries()[j]);
    recovered_at = std::min(recovered_at, j - i);
  }
  EXPECT_EQ(falses, 0u);
  EXPECT_LE(recovered_at, 2u) << "a fix within the first queries back on mapped streets";
}
