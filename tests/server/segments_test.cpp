// Query by segments (docs/protocol.md 5.5) on the tiny city: the vehicle's side
// (segmatch_vehicle) and LOCALIZE_SEGMENTS give the cloud path's answers; wrong parameters and
// malformed payloads get their ERROR codes while serving goes on.
#include "server_test_util.h"

#include "segmatch/server/map_service.h"
#include "segmatch/storage/map_reader.h"
#include "segmatch/storage/map_writer.h"
#include "segmatch/vehicle/segment_query.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>

using namespace segmatch;
using namespace segmatch::testing;

namespace {

const server::LoadedMap& loaded_map() {
  static std::shared_ptr<const server::LoadedMap> map = server::load_map(test_world().map_path);
  return *map;
}

vehicle::SegmentQuery vehicle_side() { return vehicle::SegmentQuery(server::info_of(loaded_map()).parameters_json); }

api::ErrorCode error_code_of(const api::Frame& f) {
  api::ErrorReply e;
  EXPECT_EQ(f.header.type, static_cast<uint16_t>(api::MessageType::kError));
  EXPECT_EQ(api::decode(f.payload.data(), f.payload.size(), api::Limits{}, e), api::DecodeStatus::kOk);
  return e.code;
}

void put_u32(std::vector<uint8_t>& f, size_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) f[at + i] = static_cast<uint8_t>(v >> (8 * i));
}

}  // namespace

// Localizer::localize(cloud) is extract_segments then localize_segments: without thinning and
// quantisation the two requests give bit-identical answers.
TEST(ServerSegments, UnthinnedSegmentsGiveTheCloudPathsAnswerExactly) {
  const server::LoadedMap& map = loaded_map();
  const vehicle::SegmentQuery v = vehicle_side();
  for (const Query& q : test_world().queries()) {
    api::LocalizeSegmentsRequest s;
    s.request_id = q.request.request_id;
    s.sensor_position_local = q.request.sensor_position_local;
    s.parameters_digest = v.digest();
    s.segments = v.segment(q.request.points, q.request.sensor_position_local, CloudKind::kRaw);
    ASSERT_FALSE(server::refuse_segments(map, s));
    const api::LocalizeReply a = server::localize_request(map, q.request);
    const api::LocalizeReply b = server::localize_segments_request(map, s);
    EXPECT_EQ(a.status, b.status) << q.frame;
    EXPECT_EQ(a.reason, b.reason) << q.frame;
    EXPECT_TRUE(a.T_map_local.matrix() == b.T_map_local.matrix()) << q.frame;
    EXPECT_EQ(a.matched_segment_ids, b.matched_segment_ids) << q.frame;
    EXPECT_EQ(b.timings.segment, 0.f) << "the vehicle segmented";
  }
}

TEST(ServerSegments, SegmentsOverTheWireGetTheCloudPathsStatusAndPose) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  const vehicle::SegmentQuery v = vehicle::SegmentQuery::from_info(c.info());
  EXPECT_FALSE(v.sends_esf()) << "the test map matches eigen features with L2";
  size_t same_status = 0, both = 0, wrong = 0;
  std::vector<double> cloud_bytes, segment_bytes;
  for (const Query& q : w.queries()) {
    const api::LocalizeSegmentsRequest sr = v.make_request(q.request);
    cloud_bytes.push_back(static_cast<double>(api::encode(q.request).size()));
    segment_bytes.push_back(static_cast<double>(api::encode(sr).size()));
    const api::LocalizeReply a = c.localize(q.request);
    const api::LocalizeReply b = c.localize_segments(sr);
    EXPECT_EQ(b.request_id, q.request.request_id);
    same_status += a.status == b.status;
    std::printf("[segments] frame %4zu: cloud %s, segments %s (%zu segments)\n", q.frame, api::to_string(a.status),
                api::to_string(b.status), sr.segments.size());
    if (b.status == api::LocalizeStatus::kLocalized) {
      const Pose3d T_map_sensor = b.T_map_local * q.T_local_sensor;
      wrong += position_error_m(T_map_sensor, q.T_world_sensor) > 1.0 ||
               angle_error_deg(T_map_sensor, q.T_world_sensor) > 3.0;
    }
    if (a.status != api::LocalizeStatus::kLocalized || b.status != api::LocalizeStatus::kLocalized) continue;
    ++both;
    EXPECT_LE(position_error_m(a.T_map_local, b.T_map_local), 0.01) << q.frame;
    EXPECT_LE(angle_error_deg(a.T_map_local, b.T_map_local), 0.05) << q.frame;
  }
  std::sort(cloud_bytes.begin(), cloud_bytes.end());
  std::sort(segment_bytes.begin(), segment_bytes.end());
  const double cloud_median = cloud_bytes[cloud_bytes.size() / 2],
               segments_median = segment_bytes[segment_bytes.size() / 2];
  std::printf(
      "[segments] %zu queries: same status %zu, both localized %zu, false %zu; median request %.0f KB vs %.0f KB\n",
      w.queries().size(), same_status, both, wrong, segments_median / 1024, cloud_median / 1024);
  ASSERT_GE(w.queries().size(), 8u);
  EXPECT_GE(same_status * 100, w.queries().size() * 98) << "the issue's floor: 98 % of queries";
  EXPECT_GE(both * 2, w.queries().size());
  EXPECT_EQ(wrong, 0u);
  EXPECT_LE(segments_median, 300.0 * 1024);
  EXPECT_EQ(s.server->counters().errors, 0u);
}

// Revision 10 (LOCALIZE_SEGMENTS bit 4): the vehicle that segments its own cloud sends its newest
// scans too, and gets what the cloud path with LOCALIZE bit 5 gets: the answer refined to them.
TEST(ServerSegments, NewestScansTravelWithTheSegmentsAndRefineTheAnswerAsOnTheCloudPath) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  const vehicle::SegmentQuery v = vehicle::SegmentQuery::from_info(c.info());
  size_t both = 0, refined = 0;
  for (const Query& q : w.queries()) {
    api::LocalizeRequest cloud = q.request;
    cloud.flags |= api::kFlagDetail | api::kFlagNewestScans | api::kFlagRefusalCode;
    const PointCloud near = crop_cylinder(q.request.points, q.request.sensor_position_local, 60.0);
    for (size_t i = 0; i < near.size(); i += 8) cloud.newest_points.push_back(near[i]);  // thinned, as a vehicle sends
    const api::LocalizeSegmentsRequest sr = v.make_request(cloud);
    ASSERT_TRUE(sr.flags & api::kSegmentsFlagNewestScans);
    ASSERT_TRUE(sr.flags & api::kSegmentsFlagRefusalCode) << "the refusal-code bit carries over";
    ASSERT_FALSE(sr.newest_points.empty());
    EXPECT_LT(sr.newest_points.size(), cloud.newest_points.size()) << "cropped to the map's newest.window_m";
    const api::LocalizeReply a = c.localize(cloud);
    const api::LocalizeReply b = c.localize_segments(sr);
    if (a.status != api::LocalizeStatus::kLocalized || b.status != api::LocalizeStatus::kLocalized) continue;
    ++both;
    ASSERT_TRUE(a.detail && b.detail);
    EXPECT_EQ(a.detail->window_points > 0, b.detail->window_points > 0) << q.frame;
    refined += b.detail->window_points > 0;
    EXPECT_LE(position_error_m(a.T_map_local, b.T_map_local), 0.01) << q.frame;
    EXPECT_LE(angle_error_deg(a.T_map_local, b.T_map_local), 0.05) << q.frame;
  }
  std::printf("[segments] newest scans: %zu answers on both paths, %zu refined to them\n", both, refined);
  EXPECT_GE(both * 2, w.queries().size());
  EXPECT_GE(refined * 2, both);
  EXPECT_EQ(s.server->counters().errors, 0u);
}

// Revision 5: LOCALIZE_SEGMENTS bit 2 asks for the reply's refusal code.
TEST(ServerSegments, TheRefusalCodeComesWhenAskedFor) {
  const TestWorld& w = test_world();
  RunningServer s;
  api::Client c = s.client();
  const vehicle::SegmentQuery v = vehicle::SegmentQuery::from_info(c.info());
  api::LocalizeSegmentsRequest none = v.make_request(w.queries().front().request);
  none.segments.clear();  // nothing to match
  const api::LocalizeReply plain = c.localize_segments(none);
  EXPECT_EQ(plain.status, api::LocalizeStatus::kNotLocalized);
  EXPECT_EQ(plain.refusal, api::RefusalCode::kNone) << "not asked for";
  none.flags |= api::kSegmentsFlagRefusalCode;
  const api::LocalizeReply coded = c.localize_segments(none);
  EXPECT_EQ(coded.status, api::LocalizeStatus::kNotLocalized);
  EXPECT_EQ(coded.refusal, api::RefusalCode::kTooFewSegments) << coded.reason;
}

TEST(ServerSegments, WrongDigestIsRefusedByNameAndServingGoesOn) {
  RunningServer s;
  api::Client c = s.client();
  const vehicle::SegmentQuery v = vehicle::SegmentQuery::from_info(c.info());
  api::LocalizeSegmentsRequest r = v.make_request(test_world().queries().front().request);
  r.parameters_digest ^= 1;
  try {
    c.localize_segments(r);
    ADD_FAILURE() << "segments of other parameters were localized";
  } catch (const api::ClientError& e) {
    EXPECT_EQ(e.kind, api::ClientError::Kind::kServer);
    EXPECT_EQ(e.server_code, api::ErrorCode::kParametersMismatch);
    EXPECT_NE(std::string(e.what()).find("digest"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(c.broken());
  EXPECT_EQ(c.ping(9), 9u);
  r.parameters_digest ^= 1;
  EXPECT_NO_THROW(c.localize_segments(r));
}

TEST(ServerSegments, MalformedPayloadsGetTheirCodesAndServingGoesOn) {
  RunningServer s;
  api::Client c = s.client();
  const vehicle::SegmentQuery v = vehicle::SegmentQuery::from_info(c.info());
  const std::vector<uint8_t> good = api::encode(v.make_request(test_world().queries().front().request));
  auto answer = [&](const std::vector<uint8_t>& frame) {
    c.send_raw(frame);
    return error_code_of(c.read_frame());
  };
  std::vector<uint8_t> cut(good.begin(), good.begin() + api::kHeaderBytes + 300);  // truncated
  put_u32(cut, 8, 300);
  EXPECT_EQ(answer(cut), api::ErrorCode::kBadPointCount);
  std::vector<uint8_t> f = good;
  put_u32(f, api::kHeaderBytes + 148, 3);  // segment count disagrees with the length
  EXPECT_EQ(answer(f), api::ErrorCode::kBadPointCount);
  f = good;
  const float nan = std::nanf("");
  std::memcpy(&f[api::kHeaderBytes + 156], &nan, 4);  // first centroid x
  EXPECT_EQ(answer(f), api::ErrorCode::kNonFinite);
  f = good;
  put_u32(f, api::kHeaderBytes + 8, 1u << 7);  // unknown flag bit
  EXPECT_EQ(answer(f), api::ErrorCode::kMalformed);
  std::vector<uint8_t> tiny(good.begin(), good.begin() + api::kHeaderBytes + 20);  // shorter than the fixed part
  put_u32(tiny, 8, 20);
  EXPECT_EQ(answer(tiny), api::ErrorCode::kMalformed);
  EXPECT_EQ(c.ping(4), 4u);
  EXPECT_EQ(c.localize_segments(v.make_request(test_world().queries().front().request)).request_id,
            test_world().queries().front().request.request_id);
  EXPECT_EQ(s.server->counters().errors, 5u);
}

TEST(ServerSegments, SegmentsWithoutEsfAreRefusedWhenTheMatcherComparesShapes) {
  server::LoadedMap map;
  map.config.localizer.matcher.type = MatcherType::kRandomForest;
  map.config.localizer.matcher.use_shapes = true;
  map.segments_digest = 77;
  api::LocalizeSegmentsRequest r;
  r.parameters_digest = 77;
  const std::optional<api::ErrorReply> refused = server::refuse_segments(map, r);
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->code, api::ErrorCode::kParametersMismatch);
  r.flags |= api::kSegmentsFlagEsf;
  EXPECT_FALSE(server::refuse_segments(map, r));
  map.config.localizer.matcher.type = MatcherType::kL2;
  r.flags = 0;
  EXPECT_FALSE(server::refuse_segments(map, r)) << "L2 reads eigen features only";
}

TEST(ServerSegments, ThinningKeepsEverySegmentAndAtMostTheBudget) {
  Segments segments(3);
  for (size_t i = 0; i < segments.size(); ++i) segments[i].points.resize(1000 * (i + 1));
  EXPECT_EQ(segment_point_stride(segments, 1500), 4u);
  thin_segment_points(segments, 1500);  // 6000 points: every 4th
  size_t total = 0;
  for (const Segment& s : segments) {
    EXPECT_FALSE(s.points.empty());
    total += s.points.size();
  }
  EXPECT_EQ(total, 250u + 500u + 750u);
  thin_segment_points(segments, 0);
  EXPECT_EQ(segments[0].points.size(), 250u) << "0: no thinning";
}

// Revision 11 (LOCALIZE_SEGMENTS bit 5): a vehicle with a fix sends its segments without points
// and its newest scans thinned; the server registers the scans onto the map's surface layer
// around the prior (method 2), or answers TRACKING_LOST, and a request whose segments carry
// points goes on as a full one. The suite's map has no surface layer: this test writes the
// same segments with one made of the revisit clouds placed by their true poses (the path under
// test is the server's; core/surface_tracking_test.cpp checks the registration itself).
TEST(ServerSegments, TrackingRequestsAnswerFromTheSurfaceLayerOrSayTrackingLost) {
  const TestWorld& w = test_world();
  const std::string path =
      (std::filesystem::temp_directory_path() / ("segmatch-track-" + std::to_string(::getpid()) + ".sqlite")).string();
  {
    const storage::MapReader reader = storage::MapReader::open(w.map_path);
    PointCloud layer;
    for (const Query& q : w.queries()) {
      const Pose3d T_map_local = q.T_world_sensor * q.T_local_sensor.inverse();
      for (const Point& p : q.request.points) {
        const Eigen::Vector3d m = T_map_local * p.xyz().cast<double>();
        layer.push_back(Point{float(m.x()), float(m.y()), float(m.z()), 0.f});
      }
    }
    VoxelGridConfig thin;
    thin.leaf_m = 0.25f;
    thin.min_points_per_voxel = 1;
    storage::MapMetadata meta = reader.metadata();
    storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
    writer.add_segments(reader.load_segments(), {});
    writer.set_surfaces(voxel_filter(layer, thin), 0.25f, 64.f);
    writer.commit();
  }
  const std::shared_ptr<const server::LoadedMap> map = server::load_map(path);
  const vehicle::SegmentQuery v(server::info_of(*map).parameters_json);
  size_t tracked = 0, lost = 0, wrong = 0, cloud_by_surfaces = 0;
  std::vector<double> bytes;
  for (const Query& q : w.queries()) {
    api::LocalizeRequest cloud = q.request;
    cloud.flags |= api::kFlagDetail | api::kFlagNewestScans | api::kFlagRefusalCode | api::kFlagHasPrior;
    cloud.T_map_local_prior = q.T_world_sensor * q.T_local_sensor.inverse();  // a tracker's prior: the truth
    cloud.prior_radius_m = 3.0;
    const PointCloud near = crop_cylinder(q.request.points, q.request.sensor_position_local, 60.0);
    for (size_t i = 0; i < near.size(); i += 4) cloud.newest_points.push_back(near[i]);
    const api::LocalizeSegmentsRequest full = v.make_request(cloud);
    const api::LocalizeSegmentsRequest light = v.tracking_request(full);
    ASSERT_TRUE(light.flags & api::kSegmentsFlagTrack);
    for (const Segment& g : light.segments) ASSERT_TRUE(g.points.empty());
    EXPECT_LE(light.newest_points.size(), static_cast<size_t>(v.parameters().localizer.track.max_points));
    bytes.push_back(static_cast<double>(api::encode(light).size()));
    const api::LocalizeReply r = server::localize_segments_request(*map, light);
    if (r.status == api::LocalizeStatus::kLocalized) {
      ++tracked;
      ASSERT_TRUE(r.detail && r.detail->estimate);
      EXPECT_EQ(r.detail->estimate->method, static_cast<uint8_t>(api::ReplyMethod::kSurfaces));
      const Pose3d T_map_sensor = r.T_map_local * q.T_local_sensor;
      wrong += position_error_m(T_map_sensor, q.T_world_sensor) > 0.3 ||
               angle_error_deg(T_map_sensor, q.T_world_sensor) > 1.0;
    } else {
      ++lost;
      EXPECT_EQ(r.refusal, api::RefusalCode::kTrackingLost) << r.reason;
      std::printf("[segments] frame %zu: %s\n", q.frame, r.reason.c_str());
    }
    // The truth 6 m outside a 3 m disc: never a fix.
    api::LocalizeSegmentsRequest off = light;
    off.T_map_local_prior.translation() += Eigen::Vector3d(6.0, 0.0, 0.0);
    EXPECT_NE(server::localize_segments_request(*map, off).status, api::LocalizeStatus::kLocalized) << q.frame;
    // With its segments' points the request does not stop at TRACKING_LOST: a prior too wide for
    // tracking (beyond the correlative search's 40 m) goes on to the full path and gets its answer.
    api::LocalizeSegmentsRequest wide = full, plain = full;
    wide.flags |= api::kSegmentsFlagTrack;
    wide.prior_radius_m = plain.prior_radius_m = 60.0;
    const api::LocalizeReply a = server::localize_segments_request(*map, wide),
                             b = server::localize_segments_request(*map, plain);
    EXPECT_EQ(a.status, b.status) << q.frame;
    EXPECT_NE(a.refusal, api::RefusalCode::kTrackingLost) << q.frame;
    // LOCALIZE bit 6: the same tracking on the segments the server makes of the cloud, and the
    // full path after it when it does not answer (never TRACKING_LOST: the cloud is there).
    api::LocalizeRequest tracked_cloud = cloud;
    tracked_cloud.flags |= api::kFlagTrack;
    const api::LocalizeReply t = server::localize_request(*map, tracked_cloud);
    EXPECT_NE(t.refusal, api::RefusalCode::kTrackingLost);
    if (t.status == api::LocalizeStatus::kLocalized) {
      ASSERT_TRUE(t.detail && t.detail->estimate);
      cloud_by_surfaces += t.detail->estimate->method == static_cast<uint8_t>(api::ReplyMethod::kSurfaces);
      const Pose3d T_map_sensor = t.T_map_local * q.T_local_sensor;
      wrong += position_error_m(T_map_sensor, q.T_world_sensor) > 0.3 ||
               angle_error_deg(T_map_sensor, q.T_world_sensor) > 1.0;
    }
    // The suite's map has no layer: TRACKING_LOST, by name; the vehicle library then sends the
    // full request and gets its answer.
    const api::LocalizeReply none = server::localize_segments_request(loaded_map(), light);
    EXPECT_EQ(none.refusal, api::RefusalCode::kTrackingLost);
    EXPECT_NE(none.reason.find("no surface layer"), std::string::npos) << none.reason;
    auto in_process = [](const server::LoadedMap& m) {
      return [&m](const api::LocalizeSegmentsRequest& x) { return server::localize_segments_request(m, x); };
    };
    const auto first = v.localize_tracking_first(full, in_process(loaded_map()));
    EXPECT_TRUE(first.tracking && first.lost);
    EXPECT_EQ(first.reply.status, server::localize_segments_request(loaded_map(), full).status) << q.frame;
    EXPECT_EQ(first.request_bytes, first.tracking_bytes + api::encode(full).size());
    const auto here = v.localize_tracking_first(full, in_process(*map));
    EXPECT_TRUE(here.tracking);
    EXPECT_EQ(here.lost, r.status != api::LocalizeStatus::kLocalized) << q.frame;
    EXPECT_FALSE(v.can_track(plain)) << "a 60 m prior is not tracked";
    plain.prior_radius_m = 25.0;
    EXPECT_TRUE(v.can_track(plain)) << "a 25 m prior (GNSS) is tracked: searched, then registered";
  }
  std::filesystem::remove(path);
  std::sort(bytes.begin(), bytes.end());
  std::printf("[segments] tracking requests: %zu localized on the surface layer, %zu TRACKING_LOST, median %.0f KB\n",
              tracked, lost, bytes[bytes.size() / 2] / 1024);
  // The cloud path checks the support with every segment of the cloud, the tracking request only
  // with those within track.window_m: here 9 and 6 of 9.
  EXPECT_GE(cloud_by_surfaces, tracked);
  EXPECT_GE(tracked * 2, w.queries().size());  // 6 of 9 (the others: too few matched segments for L2 on this short map)
  EXPECT_EQ(wrong, 0u);
}
