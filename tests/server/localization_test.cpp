// The server localizes simulated revisit queries sent over TCP like the in-process localizer:
// accurate poses, no false ones, map ids of the matched segments, INFO about the map, and the
// pose prior enforced.
#include "server_test_util.h"

#include <cmath>

using namespace segmatch;
using namespace segmatch::testing;

TEST(ServerLocalization, InfoDescribesTheMap) {
  RunningServer s;
  api::Client c = s.client();
  const api::InfoReply info = c.info();
  EXPECT_EQ(info.protocol_version, api::kProtocolVersion);
  EXPECT_EQ(info.map_name, "tiny-3");
  EXPECT_GT(info.segment_count, 50u);
  EXPECT_TRUE((info.extent_max.array() > info.extent_min.array()).head<2>().all());
  const io::PipelineConfig served = io::parse_pipeline_config(info.parameters_json, "INFO_REPLY");
  EXPECT_EQ(served.localizer.matcher.type, MatcherType::kL2);
  EXPECT_EQ(served.local_cloud.radius_m, test_world().config.local_cloud.radius_m);
}

TEST(ServerLocalization, RevisitQueriesLocalizeAccuratelyAndNeverFalsely) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  const size_t map_segments = c.info().segment_count;
  size_t localized = 0, accurate = 0, wrong = 0;
  for (const Query& q : w.queries()) {
    const api::LocalizeReply r = c.localize(q.request);
    EXPECT_EQ(r.request_id, q.request.request_id);
    std::printf("[server]   frame %4zu: %s, %u inliers, support %u, %.0f ms %s\n", q.frame, api::to_string(r.status),
                r.inliers, r.support, r.timings.server_total, r.reason.c_str());
    if (r.status != api::LocalizeStatus::kLocalized) continue;
    ++localized;
    EXPECT_EQ(r.matched_segment_ids.size(), r.inliers);
    for (uint64_t id : r.matched_segment_ids) EXPECT_LT(id, map_segments * 4) << "a map id, not garbage";
    EXPECT_GT(r.timings.total, 0.f);
    EXPECT_GE(r.timings.server_total, r.timings.total);
    const Pose3d T_map_sensor = r.T_map_local * q.T_local_sensor;
    const double err_m = position_error_m(T_map_sensor, q.T_world_sensor);
    const double err_deg = angle_error_deg(T_map_sensor, q.T_world_sensor);
    accurate += err_m <= 0.2 && err_deg <= 1.0;
    wrong += err_m > 1.0 || err_deg > 3.0;
    std::printf("[server]   frame %4zu: error %.3f m %.2f deg, confidence %.2f\n", q.frame, err_m, err_deg,
                r.confidence);
  }
  std::printf("[server] revisit: %zu queries, %zu localized, %zu within 0.2 m / 1 deg, %zu false\n", w.queries().size(),
              localized, accurate, wrong);
  ASSERT_GE(w.queries().size(), 8u);
  EXPECT_EQ(wrong, 0u);
  EXPECT_GE(accurate * 2, w.queries().size()) << "most queries localize accurately";
  const server::ServerCounters counters = s.server->counters();
  EXPECT_EQ(counters.localize_requests, w.queries().size() + 0);
  EXPECT_EQ(counters.localized, localized);
  EXPECT_EQ(counters.errors, 0u);
}

TEST(ServerLocalization, PosePriorIsEnforced) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  for (const Query& q : w.queries()) {
    const api::LocalizeReply free = c.localize(q.request);
    if (free.status != api::LocalizeStatus::kLocalized) continue;
    api::LocalizeRequest with_prior = q.request;
    with_prior.flags = api::kFlagHasPrior;
    with_prior.prior_radius_m = 20.0;
    with_prior.T_map_local_prior = free.T_map_local;
    with_prior.T_map_local_prior.translation() += Eigen::Vector3d(5.0, -3.0, 0.0);  // a fair guess
    const api::LocalizeReply fair = c.localize(with_prior);
    EXPECT_EQ(fair.status, api::LocalizeStatus::kLocalized) << fair.reason;
    EXPECT_LT((fair.T_map_local.translation() - free.T_map_local.translation()).norm(), 0.2);
    // A wrong prior narrows the search to where the place is not: no pose, never a false one
    // (docs/protocol.md 5.4, revision 2).
    with_prior.T_map_local_prior.translation() += Eigen::Vector3d(150.0, 0.0, 0.0);
    const api::LocalizeReply far = c.localize(with_prior);
    EXPECT_NE(far.status, api::LocalizeStatus::kLocalized) << far.reason;
    // Radius 0 keeps revision 1's meaning: a global search, then OUTSIDE_PRIOR with the pose.
    with_prior.prior_radius_m = 0.0;
    const api::LocalizeReply reject_only = c.localize(with_prior);
    EXPECT_EQ(reject_only.status, api::LocalizeStatus::kOutsidePrior);
    EXPECT_EQ(reject_only.refusal, api::RefusalCode::kNone) << "not asked for (revision 5, rule 2)";
    EXPECT_FALSE(reject_only.reason.empty());
    with_prior.flags |= api::kFlagRefusalCode;
    const api::LocalizeReply coded = c.localize(with_prior);
    EXPECT_EQ(coded.status, api::LocalizeStatus::kOutsidePrior);
    EXPECT_EQ(coded.refusal, api::RefusalCode::kOutsidePrior) << coded.reason;
    EXPECT_LT((reject_only.T_map_local.translation() - free.T_map_local.translation()).norm(), 0.2);
    return;
  }
  FAIL() << "no query localized";
}

TEST(ServerLocalization, OnlyPointsInTheLocalCylinderAreUsed) {
  // The same query with the sensor announced 500 m away: nothing of the cloud is within the
  // local cloud radius of it, so there is nothing to localize.
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  api::LocalizeRequest far = w.queries().front().request;
  far.sensor_position_local += Eigen::Vector3d(500, 0, 0);
  const api::LocalizeReply r = c.localize(far);
  EXPECT_EQ(r.status, api::LocalizeStatus::kNotLocalized);
  EXPECT_FALSE(r.reason.empty());
  EXPECT_EQ(r.refusal, api::RefusalCode::kNone) << "not asked for";
  far.flags |= api::kFlagRefusalCode;
  const api::LocalizeReply coded = c.localize(far);
  EXPECT_EQ(coded.refusal, api::RefusalCode::kTooFewSegments) << coded.reason;
  EXPECT_EQ(coded.reason, r.reason) << "the words stay";
}

// Revision 8 (LOCALIZE bit 5): the vehicle's newest scans travel with the cloud and the server
// refines its answer to them; the detail block says by how much and with how many points.
// Newest points that belong elsewhere (the cloud lifted 5 m) leave the answer as it was.
TEST(ServerLocalization, NewestScansRefineTheAnswerOverTheWire) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  size_t refined = 0, localized = 0;
  for (const Query& q : w.queries()) {
    api::LocalizeRequest plain = q.request;
    plain.flags |= api::kFlagDetail;
    const api::LocalizeReply without = c.localize(plain);
    if (without.status != api::LocalizeStatus::kLocalized) continue;
    ++localized;
    api::LocalizeRequest newest = plain;
    newest.flags |= api::kFlagNewestScans;
    newest.newest_points = crop_cylinder(q.request.points, q.request.sensor_position_local, 25.0);
    const api::LocalizeReply with = c.localize(newest);
    ASSERT_EQ(with.status, api::LocalizeStatus::kLocalized) << "the newest scans never refuse a query";
    ASSERT_TRUE(with.detail.has_value());
    refined += with.detail->window_points > 0;
    const Pose3d T_map_sensor = with.T_map_local * q.T_local_sensor;
    EXPECT_LE(position_error_m(T_map_sensor, q.T_world_sensor), 0.2) << "frame " << q.frame;
    EXPECT_LE(angle_error_deg(T_map_sensor, q.T_world_sensor), 1.0) << "frame " << q.frame;
    if (with.detail->window_points > 0) {
      EXPECT_NEAR(with.detail->window_warp_m,
                  ((with.T_map_local.translation() - without.T_map_local.translation()) +
                   (with.T_map_local.linear() - without.T_map_local.linear()) * q.request.sensor_position_local)
                      .norm(),
                  1e-3)
          << "the warp is how far the newest scans moved the answer at the sensor";
    }
    api::LocalizeRequest elsewhere = newest;
    for (Point& p : elsewhere.newest_points) p.z += 5.0f;
    const api::LocalizeReply lifted = c.localize(elsewhere);
    ASSERT_EQ(lifted.status, api::LocalizeStatus::kLocalized);
    EXPECT_TRUE(lifted.T_map_local.isApprox(without.T_map_local, 1e-9)) << "frame " << q.frame;
    EXPECT_EQ(lifted.detail->window_points, 0u);
  }
  std::printf("[server] newest scans: %zu of %zu localized queries refined to them\n", refined, localized);
  ASSERT_GE(localized, 4u);
  EXPECT_GE(refined * 2, localized) << "most answers are refined to the newest scans";
}
