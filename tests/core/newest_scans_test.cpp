// The sensor's pose now from the vehicle's newest scans (Localizer::refine_to_newest_scans,
// NewestScansConfig): an answer a little off is brought to the truth by scans that agree with
// the map, and left as it is by scans that do not, by an answer that is not localized, or when
// the stage is off.
#include "segmatch/core/localization/localizer.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <cmath>

namespace segmatch {
namespace {

using test::pole_street;
using test::transformed;

constexpr double kDeg = M_PI / 180.0;

Pose3d T_query_map() {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(-12.0, 30.0, 0.5);
  return T;
}

// A localized answer whose pose is off the truth by `shift_m` along x and `turn_deg` of yaw
// (about the sensor), as a whole cloud warped by drifting odometry would give.
LocalizationResult answer_off(const Pose3d& T_map_query_true, const Eigen::Vector3d& sensor_query, double shift_m,
                              double turn_deg) {
  Pose3d offset = Pose3d::Identity();
  offset.linear() = Eigen::AngleAxisd(turn_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d s = T_map_query_true * sensor_query;
  offset.translation() = s - offset.linear() * s + Eigen::Vector3d(shift_m, 0.0, 0.0);
  LocalizationResult r;
  r.status = LocalizationStatus::kLocalized;
  r.T_map_query = offset * T_map_query_true;
  return r;
}

struct Street {
  LocalizerConfig config = test::street_localizer_config();
  PointCloud map_cloud = test::street_with_platforms();
  Eigen::Vector3f sensor_map{25.f, 0.f, 2.f};
  Pose3d T_query = T_query_map();  // T_query_map: map points into the vehicle's frame
  Localizer localizer() const {
    return Localizer(config, extract_segments(map_cloud, sensor_map, config.segmentation));
  }
  Eigen::Vector3d sensor_query() const { return T_query * sensor_map.cast<double>(); }
  PointCloud newest() const { return transformed(map_cloud, T_query); }
};

double error_m(const LocalizationResult& r, const Street& s) {
  return (r.T_map_query * s.sensor_query() - s.sensor_map.cast<double>()).norm();
}
double error_deg(const LocalizationResult& r, const Street& s) {
  return Eigen::AngleAxisd((r.T_map_query * s.T_query).linear()).angle() / kDeg;
}

TEST(NewestScans, BringAnAnswerThatIsALittleOffToTheTruth) {
  const Street s;
  const Localizer localizer = s.localizer();
  LocalizationResult r = answer_off(s.T_query.inverse(), s.sensor_query(), 0.3, 0.5);
  ASSERT_GT(error_m(r, s), 0.25);
  localizer.refine_to_newest_scans(s.newest(), s.sensor_query().cast<float>(), r);
  EXPECT_LT(error_m(r, s), 0.02);
  EXPECT_LT(error_deg(r, s), 0.05);
  EXPECT_NEAR(r.window_warp_m, 0.3, 0.03) << "the warp is how far the answer moved at the sensor";
  EXPECT_NEAR(r.window_warp_deg, 0.5, 0.05);
  EXPECT_GT(r.window_points, 300u);
  EXPECT_FALSE(r.covariance.isZero()) << "the answer's covariance is the newest scans'";
}

TEST(NewestScans, LeaveTheAnswerWhenTheyDoNotQualify) {
  const Street s;
  const Localizer localizer = s.localizer();
  const Eigen::Vector3f sensor = s.sensor_query().cast<float>();
  auto unchanged = [&](LocalizationResult r, const PointCloud& newest, const Localizer& l, const char* why) {
    const Pose3d before = r.T_map_query;
    l.refine_to_newest_scans(newest, sensor, r);
    EXPECT_TRUE(r.T_map_query.isApprox(before, 1e-12)) << why;
    EXPECT_EQ(r.window_points, 0u) << why;
  };
  const LocalizationResult off = answer_off(s.T_query.inverse(), s.sensor_query(), 0.3, 0.5);
  unchanged(off, {}, localizer, "no newest scans");
  PointCloud elsewhere = transformed(s.map_cloud, T_query_map() * Pose3d(Eigen::Translation3d(0.0, 0.0, 30.0)));
  unchanged(off, elsewhere, localizer, "scans of a place 30 m above the map fit nothing there");
  const PointCloud all = s.newest();
  const PointCloud few(all.begin(), all.begin() + 50);
  unchanged(off, few, localizer, "too few points");
  LocalizationResult refused = off;
  refused.status = LocalizationStatus::kNotLocalized;
  unchanged(refused, s.newest(), localizer, "not localized: nothing to refine");
  // An answer 3 m off is not a starting point: whatever the scans fit from there, it is
  // farther than max_shift_m from the answer, or not the truth.
  const LocalizationResult far = answer_off(s.T_query.inverse(), s.sensor_query(), 3.0, 0.0);
  unchanged(far, s.newest(), localizer, "the newest scans may move an answer by at most max_shift_m");
  Street off_switch;
  off_switch.config.newest.enabled = false;
  unchanged(off, s.newest(), off_switch.localizer(), "disabled");
}

// Segments alone hold the height, roll and pitch weakly (the poles and walls are vertical);
// with the surface layer the scans keep their ground and register onto it: an answer off in
// height and tilted comes back to the truth.
TEST(NewestScans, OntoTheSurfaceLayerTheGroundHoldsHeightRollAndPitch) {
  Street s;
  const Localizer segments_only = s.localizer();
  const PointCloud surfaces = test::with_ground(s.map_cloud);
  const Localizer layered(s.config, segments_only.targets(), nullptr, nullptr,
                          std::make_shared<test::InMemorySurfaces>(surfaces));
  LocalizationResult off = answer_off(s.T_query.inverse(), s.sensor_query(), 0.0, 0.0);
  Pose3d tilt = Pose3d::Identity();  // 0.6 deg of roll and 0.12 m of height about the sensor
  const Eigen::Vector3d at = s.sensor_map.cast<double>();
  tilt.linear() = Eigen::AngleAxisd(0.6 * kDeg, Eigen::Vector3d::UnitX()).toRotationMatrix();
  tilt.translation() = at - tilt.linear() * at + Eigen::Vector3d(0.0, 0.0, 0.12);
  off.T_map_query = tilt * off.T_map_query;
  ASSERT_GT(error_m(off, s), 0.1);
  LocalizationResult r = off;
  layered.refine_to_newest_scans(transformed(surfaces, s.T_query), s.sensor_query().cast<float>(), r);
  ASSERT_GT(r.window_points, 0u);
  EXPECT_LT(error_m(r, s), 0.02);
  EXPECT_LT(error_deg(r, s), 0.05);
}

// Newest scans that see what the surface layer never saw (here: buildings where the map has
// open ground) mean the sensor is off the map, e.g. on an unmapped street: the answer, a pose
// extrapolated through the odometry's warp, is refused by name. Off, or without a layer (the
// segments cover too little to say it), the answer stands as it was.
TEST(NewestScans, SeeingWhatTheSurfaceLayerNeverSawRefusesTheAnswerAsOffMap) {
  Street s;
  const Localizer segments_only = s.localizer();
  const PointCloud surfaces = test::with_ground(s.map_cloud);
  PointCloud unmapped;  // a block of buildings where the map has open ground
  for (float x = 0.f; x <= 50.f; x += 10.f)
    for (float y : {-15.f, 10.f}) test::add_box(unmapped, x, y, 6.f, 4.f, 8.f);
  const PointCloud newest = transformed(unmapped, s.T_query);
  const Eigen::Vector3f sensor = s.sensor_query().cast<float>();
  const LocalizationResult answer = answer_off(s.T_query.inverse(), s.sensor_query(), 0.1, 0.2);

  const Localizer layered(s.config, segments_only.targets(), nullptr, nullptr,
                          std::make_shared<test::InMemorySurfaces>(surfaces));
  LocalizationResult r = answer;
  layered.refine_to_newest_scans(newest, sensor, r);
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kOffMap) << r.reason;
  EXPECT_NE(r.newest_refusal, RegistrationRefusal::kNone) << r.newest_reason;
  EXPECT_NE(r.reason.find("newest scans do not lie on the map's surfaces"), std::string::npos) << r.reason;
  EXPECT_NE(r.reason.find("fitness"), std::string::npos) << r.reason;
  EXPECT_TRUE(r.covariance.isZero());

  // The same scans of the mapped street are not refused: the test's scene is what decides.
  LocalizationResult mapped = answer;
  layered.refine_to_newest_scans(transformed(surfaces, s.T_query), sensor, mapped);
  EXPECT_TRUE(mapped.localized());
  EXPECT_GT(mapped.window_points, 0u);

  // An answer 1.3 m off the truth: the same scans settle at the truth, farther than max_shift_m
  // (1 m) from it. The sensor's own view puts it elsewhere: refused, by its own name.
  LocalizationResult far = answer_off(s.T_query.inverse(), s.sensor_query(), 1.3, 0.0);
  layered.refine_to_newest_scans(transformed(surfaces, s.T_query), sensor, far);
  EXPECT_FALSE(far.localized());
  EXPECT_EQ(far.refusal, Refusal::kNewestScansDisagree) << far.reason;
  EXPECT_EQ(far.newest_refusal, RegistrationRefusal::kOutsidePrior) << far.newest_reason;

  Street off_switch;
  off_switch.config.newest.refuse_off_map = false;
  const Localizer lenient(off_switch.config, segments_only.targets(), nullptr, nullptr,
                          std::make_shared<test::InMemorySurfaces>(surfaces));
  for (const Localizer* l : {&lenient, &segments_only}) {
    LocalizationResult kept = answer;
    l->refine_to_newest_scans(newest, sensor, kept);
    EXPECT_TRUE(kept.localized());
    EXPECT_TRUE(kept.T_map_query.isApprox(answer.T_map_query, 1e-12));
    EXPECT_EQ(kept.window_points, 0u);
  }
}

TEST(NewestScans, ConfigRefusesBadValuesByName) {
  NewestScansConfig c;
  EXPECT_NO_THROW(c.validate());
  c.leaf_m = 0.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.min_fitness = 1.5f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.max_shift_m = std::nanf("");
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
