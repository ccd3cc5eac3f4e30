// Tracking on the surface layer (Localizer::track, SurfaceTrackingConfig): the newest scans
// registered onto the layer around a tracker's prior, checked against the query's segments
// (centroids and features only: a tracking request carries no segment points).
#include "segmatch/core/localization/localizer.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace segmatch {
namespace {

using test::transformed;

constexpr double kDeg = M_PI / 180.0;

struct Street {
  LocalizerConfig config = test::street_localizer_config();
  PointCloud map_cloud = test::street_with_platforms();
  Eigen::Vector3f sensor_map{25.f, 0.f, 2.f};
  Pose3d T_query = [] {  // map points into the vehicle's odometry frame
    Pose3d T = Pose3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(-12.0, 30.0, 0.5);
    return T;
  }();
  Segments map_segments() const { return extract_segments(map_cloud, sensor_map, config.segmentation); }
  Localizer layered() const {
    return Localizer(config, map_segments(), nullptr, nullptr,
                     std::make_shared<test::InMemorySurfaces>(test::with_ground(map_cloud)));
  }
  Eigen::Vector3d sensor_query() const { return T_query * sensor_map.cast<double>(); }
  PointCloud newest() const { return transformed(test::with_ground(map_cloud), T_query); }
  // The query's segments as a tracking request brings them: no points.
  Segments query_segments() const {
    Segments s = extract_segments(transformed(map_cloud, T_query), sensor_query().cast<float>(), config.segmentation);
    for (Segment& g : s) g.points.clear();
    return s;
  }
  // A tracker's prior: the truth moved by shift_m along x and turned by turn_deg about the sensor.
  PosePrior prior(double shift_m, double turn_deg, double radius_m = 3.0) const {
    Pose3d offset = Pose3d::Identity();
    offset.linear() = Eigen::AngleAxisd(turn_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Vector3d s = sensor_map.cast<double>();
    offset.translation() = s - offset.linear() * s + Eigen::Vector3d(shift_m, 0.0, 0.0);
    PosePrior p;
    p.T_map_query = offset * T_query.inverse();
    p.radius_m = radius_m;
    p.max_rotation_deg = 5.0;
    return p;
  }
  double error_m(const LocalizationResult& r) const {
    return (r.T_map_query * sensor_query() - sensor_map.cast<double>()).norm();
  }
};

TEST(SurfaceTracking, RegistersTheNewestScansFromATrackersPrior) {
  const Street s;
  const Localizer localizer = s.layered();
  for (const auto& [shift_m, turn_deg] : {std::pair{0.0, 0.0}, {0.8, 2.0}, {-1.2, -3.0}}) {
    const LocalizationResult r =
        localizer.track(s.query_segments(), s.newest(), s.sensor_query().cast<float>(), s.prior(shift_m, turn_deg));
    ASSERT_TRUE(r.localized()) << shift_m << " m: " << r.reason;
    EXPECT_EQ(r.method, LocalizationMethod::kSurfaces);
    EXPECT_LT(s.error_m(r), 0.02) << shift_m << " m";
    EXPECT_LT(Eigen::AngleAxisd((r.T_map_query * s.T_query).linear()).angle() / kDeg, 0.05);
    EXPECT_FALSE(r.covariance.isZero());
    EXPECT_GE(r.support, static_cast<size_t>(s.config.registration.min_support));
    EXPECT_GT(r.window_points, static_cast<size_t>(s.config.track.min_points));
  }
}

TEST(SurfaceTracking, RefusesByNameWhatItCannotAnswer) {
  const Street s;
  const Localizer layered = s.layered();
  const Eigen::Vector3f sensor = s.sensor_query().cast<float>();
  auto lost = [&](const LocalizationResult& r, const char* words, const char* why) {
    EXPECT_FALSE(r.localized()) << why;
    EXPECT_EQ(r.refusal, Refusal::kTrackingLost) << why;
    EXPECT_NE(r.reason.find(words), std::string::npos) << why << ": " << r.reason;
    EXPECT_TRUE(r.covariance.isZero()) << why;
  };
  const Localizer no_layer(s.config, s.map_segments());
  lost(no_layer.track(s.query_segments(), s.newest(), sensor, s.prior(0.3, 0.0)), "no surface layer",
       "map without a layer");
  lost(layered.track(s.query_segments(), s.newest(), sensor, s.prior(0.3, 0.0, 60.0)), "wider than",
       "a prior beyond the search's 40 m");
  Street no_search = s;
  no_search.config.search.enabled = false;
  lost(no_search.layered().track(s.query_segments(), s.newest(), sensor, s.prior(0.3, 0.0, 20.0)), "wider than",
       "a GNSS-wide prior with the correlative search off");
  const PointCloud all = s.newest();
  lost(layered.track(s.query_segments(), PointCloud(all.begin(), all.begin() + 50), sensor, s.prior(0.3, 0.0)),
       "newest points near the sensor", "too few newest points");
  // Scans that fit (ground and walls) but segments of another place: the support check refuses.
  Segments elsewhere = s.query_segments();
  for (Segment& g : elsewhere) g.centroid += Eigen::Vector3f(0.f, 0.f, 15.f);
  lost(layered.track(elsewhere, s.newest(), sensor, s.prior(0.3, 0.0)), "query segments land on map segments",
       "segments that land on nothing");
  Street off = s;
  off.config.track.enabled = false;
  lost(off.layered().track(s.query_segments(), s.newest(), sensor, s.prior(0.3, 0.0)), "track.enabled", "switched off");
}

// A prior whose disc does not hold the truth never becomes a fix: the registration either
// reaches the truth (outside the disc: refused) or stays where no gate passes.
TEST(SurfaceTracking, AWrongPriorNeverBecomesAFix) {
  const Street s;
  const Localizer localizer = s.layered();
  for (double shift_m : {4.0, -5.0, 8.0, 15.0}) {
    const LocalizationResult r =
        localizer.track(s.query_segments(), s.newest(), s.sensor_query().cast<float>(), s.prior(shift_m, 0.0));
    EXPECT_FALSE(r.localized() && s.error_m(r) > 1.0) << shift_m << " m: a false fix " << s.error_m(r) << " m off";
    EXPECT_FALSE(r.localized()) << shift_m << " m: the truth is outside the prior's 3 m";
  }
}

// A GNSS-wide prior (wider than registration takes): the correlative search over the layer finds
// the peaks, tracking from them answers at the truth; the truth outside such a disc never does.
TEST(SurfaceTracking, WidePriorsAreSearchedThenRegistered) {
  const Street s;
  const Localizer localizer = s.layered();
  const Eigen::Vector3f sensor = s.sensor_query().cast<float>();
  ASSERT_GT(20.0, s.config.registration.max_prior_radius_m)
      << "the test is about priors registration alone does not take";
  for (const auto& [shift_m, turn_deg] : {std::pair{12.0, 0.0}, {-15.0, 4.0}}) {
    const LocalizationResult r =
        localizer.track(s.query_segments(), s.newest(), sensor, s.prior(shift_m, turn_deg, 20.0));
    ASSERT_TRUE(r.localized()) << shift_m << " m: " << r.reason;
    EXPECT_EQ(r.method, LocalizationMethod::kSurfaces);
    EXPECT_LT(s.error_m(r), 0.05) << shift_m << " m";
    EXPECT_LT(Eigen::AngleAxisd((r.T_map_query * s.T_query).linear()).angle() / kDeg, 0.1);
  }
  for (double shift_m : {30.0, -28.0}) {
    const LocalizationResult r = localizer.track(s.query_segments(), s.newest(), sensor, s.prior(shift_m, 0.0, 15.0));
    EXPECT_FALSE(r.localized()) << shift_m << " m: the truth is outside the prior's 15 m, " << s.error_m(r) << " m off";
    EXPECT_EQ(r.refusal, Refusal::kTrackingLost);
  }
}

// Repeated structure (two identical blocks 45 m apart): a wide prior whose disc holds only the
// look-alike finds the look-alike by search and registration, and every gate passes there. The
// truth, outside the disc, fits as well: the shifted support over the prior's diameter refuses.
TEST(SurfaceTracking, ALookAlikeInAWidePriorIsRefusedNotAnswered) {
  Street s;
  const PointCloud block = s.map_cloud;
  PointCloud twin = transformed(block, Pose3d(Eigen::Translation3d(0.0, 45.0, 0.0)));
  s.map_cloud.insert(s.map_cloud.end(), twin.begin(), twin.end());
  PointCloud layer = test::with_ground(s.map_cloud);
  const PointCloud twin_ground = transformed(test::with_ground({}), Pose3d(Eigen::Translation3d(0.0, 45.0, 0.0)));
  layer.insert(layer.end(), twin_ground.begin(), twin_ground.end());
  const Localizer localizer(s.config, s.map_segments(), nullptr, nullptr,
                            std::make_shared<test::InMemorySurfaces>(layer));
  // The vehicle sees its own block: the query is the original block alone.
  Segments query =
      extract_segments(transformed(block, s.T_query), s.sensor_query().cast<float>(), s.config.segmentation);
  for (Segment& g : query) g.points.clear();
  const PointCloud newest = transformed(test::with_ground(block), s.T_query);
  PosePrior prior = s.prior(0.0, 0.0, 25.0);  // 25 m around a centre 32 m from the truth, 13 m from the twin
  prior.T_map_query = Pose3d(Eigen::Translation3d(0.0, 32.0, 0.0)) * prior.T_map_query;
  ASSERT_LE(prior.radius_m, max_tracked_radius_m(s.config));
  const LocalizationResult r = localizer.track(query, newest, s.sensor_query().cast<float>(), prior);
  EXPECT_FALSE(r.localized()) << "answered " << s.error_m(r) << " m off";
  EXPECT_EQ(r.refusal, Refusal::kTrackingLost) << r.reason;
  EXPECT_NE(r.reason.find("fit elsewhere"), std::string::npos) << r.reason;
  // A prior whose diameter (30 m) does not reach the twin from the truth answers at the truth:
  // the refusal is the twin's. (With 25 m around the truth the twin, 45 m away, is within the
  // diameter and the answer is refused too: the objects alone cannot tell the blocks apart.)
  PosePrior fair = s.prior(0.0, 0.0, 15.0);
  fair.T_map_query = Pose3d(Eigen::Translation3d(0.0, -5.0, 0.0)) * fair.T_map_query;
  const LocalizationResult t = localizer.track(query, newest, s.sensor_query().cast<float>(), fair);
  ASSERT_TRUE(t.localized()) << t.reason;
  EXPECT_LT(s.error_m(t), 0.05);
}

// Scans that fit the surfaces at the pose while the objects fit better elsewhere along the
// street (a look-alike facade, the truth just outside the prior): the support of the query's
// segments at the shifted pose refuses the answer by name.
TEST(SurfaceTracking, ObjectsThatFitBetterElsewhereRefuseTheAnswer) {
  const Street s;
  const Localizer localizer = s.layered();
  // The query's own segments land at the registered pose; the same number again, seen as if the
  // street were moved 6 m along x, land at a pose 6 m away: as much support there as here.
  Segments query = s.query_segments();
  const size_t here = query.size();
  const Pose3d moved = s.T_query * Pose3d(Eigen::Translation3d(6.0, 0.0, 0.0));
  for (Segment g :
       extract_segments(transformed(s.map_cloud, moved), s.sensor_query().cast<float>(), s.config.segmentation)) {
    g.points.clear();
    query.push_back(g);
  }
  ASSERT_GT(query.size(), here);
  const LocalizationResult r = localizer.track(query, s.newest(), s.sensor_query().cast<float>(), s.prior(0.3, 0.0));
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kTrackingLost);
  EXPECT_EQ(r.registration_refusal, RegistrationRefusal::kAmbiguous) << r.reason;
  EXPECT_NE(r.reason.find("the objects fit elsewhere"), std::string::npos) << r.reason;
  Street lenient = s;
  lenient.config.track.max_shifted_support = 10.0f;  // the check off, in effect
  EXPECT_TRUE(lenient.layered().track(query, s.newest(), s.sensor_query().cast<float>(), s.prior(0.3, 0.0)).localized())
      << "without the check the same request is answered: the test's scene is what decides";
}

// Away from a narrow prior a pose needs track.min_matched_segments matched pairs, or only
// min_matched_segments_near_prior when at least min_support_for_fewer_matched segments land on
// map segments under it. Here no pose can reach the full count: the support decides.
TEST(SurfaceTracking, ADenseLayoutOfObjectsNeedsFewerMatchedPairs) {
  Street s;
  s.config.track.min_matched_segments = 1000;
  const PosePrior prior = s.prior(1.0, 0.0, 5.0);  // wider than track.fine_first_max_radius_m
  ASSERT_GT(prior.radius_m, s.config.track.fine_first_max_radius_m);
  const Segments query = s.query_segments();
  s.config.track.min_support_for_fewer_matched = 0;  // off
  const LocalizationResult off = s.layered().track(query, s.newest(), s.sensor_query().cast<float>(), prior);
  EXPECT_FALSE(off.localized());
  EXPECT_EQ(off.registration_refusal, RegistrationRefusal::kLowSupport) << off.reason;
  ASSERT_GE(off.support, 10u) << "the scene gives enough support for the rule to matter";
  s.config.track.min_support_for_fewer_matched = static_cast<int>(off.support);
  const LocalizationResult dense = s.layered().track(query, s.newest(), s.sensor_query().cast<float>(), prior);
  ASSERT_TRUE(dense.localized()) << dense.reason;
  EXPECT_LT(s.error_m(dense), 0.05);
  s.config.track.min_support_for_fewer_matched = static_cast<int>(off.support) + 1;
  const LocalizationResult sparse = s.layered().track(query, s.newest(), s.sensor_query().cast<float>(), prior);
  EXPECT_FALSE(sparse.localized());
  EXPECT_NE(sparse.reason.find("landing"), std::string::npos) << sparse.reason;
}

// When tracking does not answer and the segments path refuses too, the refusal says why each
// did: the operator sees tracking's reason, not only the fallback's.
TEST(SurfaceTracking, AFallbackRefusalKeepsTrackingsReason) {
  const Street s;
  const Localizer localizer = s.layered();
  // A prior turned 20 degrees from the truth, with a 5 degree tolerance: neither path may answer.
  const LocalizationResult r =
      localizer.localize_tracking_first(transformed(s.map_cloud, s.T_query), s.sensor_query().cast<float>(),
                                        CloudKind::kRaw, s.newest(), s.prior(0.0, 20.0), Deadline{});
  ASSERT_FALSE(r.localized()) << "answered " << s.error_m(r) << " m off";
  EXPECT_NE(r.reason.find(" (tracking on the surface layer: "), std::string::npos) << r.reason;
  LocalizationResult answered;
  answered.status = LocalizationStatus::kLocalized;
  keep_tracking_reason("tracking on the surface layer: why", answered);
  EXPECT_TRUE(answered.reason.empty()) << "an answer carries no reason";
}

// The tracking path segments a cloud without describing it: a tracked answer describes only the
// segments its pose puts on map segments, and is the answer of the fully described query; a
// refusal describes the rest before the segments path matches them.
TEST(SurfaceTracking, TrackingFirstDescribesOnlyTheSegmentsItChecks) {
  const Street s;
  // The map lacks its four segments farthest from the sensor: their query counterparts land on
  // nothing, and need no descriptor.
  Segments targets = s.map_segments();
  std::sort(targets.begin(), targets.end(), [&](const Segment& a, const Segment& b) {
    return (a.centroid - s.sensor_map).norm() < (b.centroid - s.sensor_map).norm();
  });
  targets.resize(targets.size() - 4);
  const Localizer localizer(s.config, targets, nullptr, nullptr,
                            std::make_shared<test::InMemorySurfaces>(test::with_ground(s.map_cloud)));
  const PointCloud cloud = transformed(s.map_cloud, s.T_query);
  const Eigen::Vector3f sensor = s.sensor_query().cast<float>();
  const PosePrior prior = s.prior(0.8, 2.0);
  const LocalizationResult lazy =
      localizer.localize_tracking_first(cloud, sensor, CloudKind::kRaw, s.newest(), prior, Deadline{});
  const LocalizationResult full =
      localizer.track(extract_segments(cloud, sensor, s.config.segmentation), s.newest(), sensor, prior);
  ASSERT_TRUE(lazy.localized()) << lazy.reason;
  ASSERT_TRUE(full.localized()) << full.reason;
  EXPECT_TRUE(lazy.T_map_query.isApprox(full.T_map_query, 0.0)) << "the same pose, bit for bit";
  EXPECT_EQ(lazy.support, full.support);
  ASSERT_EQ(lazy.inliers.size(), full.inliers.size());
  ASSERT_EQ(lazy.query.size(), full.query.size());
  size_t described = 0;
  for (size_t i = 0; i < lazy.query.size(); ++i) {
    if (!lazy.query[i].has_eigen) continue;
    ++described;
    EXPECT_EQ(lazy.query[i].eigen, full.query[i].eigen) << "segment " << i;
    EXPECT_EQ(lazy.query[i].esf, full.query[i].esf) << "segment " << i;
  }
  EXPECT_GE(described, lazy.support) << "every landing segment is described";
  EXPECT_LT(described, lazy.query.size()) << "the scene has segments the pose does not check";
  // A prior turned 20 degrees (5 allowed): tracking refuses, the segments path gets every
  // segment described.
  const LocalizationResult refused =
      localizer.localize_tracking_first(cloud, sensor, CloudKind::kRaw, s.newest(), s.prior(0.0, 20.0), Deadline{});
  ASSERT_FALSE(refused.localized());
  ASSERT_FALSE(refused.query.empty());
  for (const Segment& g : refused.query) EXPECT_TRUE(g.has_eigen);
}

TEST(SurfaceTracking, ConfigRefusesBadValuesByName) {
  SurfaceTrackingConfig c;
  EXPECT_NO_THROW(c.validate());
  c.leaf_m = 0.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.min_fitness = 1.2f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.min_points = 2;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.max_points = c.min_points - 1;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.max_shifted_support = 0.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.fine_first_max_radius_m = -1.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
