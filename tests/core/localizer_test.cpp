// The Localizer on synthetic scenes with exact answers: a street of distinct objects is
// localized at the true pose; a street of identical, evenly spaced poles is refused as
// ambiguous (any shift by the spacing explains it as well); bad input is refused, not thrown.
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/detail/random.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <cmath>

namespace segmatch {
namespace {

using test::add_box;
using test::add_cylinder;
using test::pole_street;
using test::transformed;

LocalizerConfig config() { return test::street_localizer_config(); }

Pose3d T_query_map() {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(-12.0, 30.0, 0.5);
  return T;
}

TEST(Localizer, LocalizesAStreetOfDistinctObjectsAtTheTruePose) {
  const LocalizerConfig c = config();
  const PointCloud map_cloud = pole_street(true);
  const Localizer localizer(c, extract_segments(map_cloud, Eigen::Vector3f(25, 0, 2), c.segmentation));
  const Pose3d T = T_query_map();
  const LocalizationResult r =
      localizer.localize(transformed(map_cloud, T), (T.cast<float>() * Eigen::Vector3f(25, 0, 2)));
  ASSERT_TRUE(r.localized()) << r.reason;
  const Pose3d error = r.T_map_query * T;  // identity if exact
  EXPECT_LT(error.translation().norm(), 0.02);
  EXPECT_LT(Eigen::AngleAxisd(error.linear()).angle(), 0.002);
  EXPECT_GE(r.support, 15u);
  EXPECT_GT(r.confidence, 0.5f);
  EXPECT_GE(r.timings.total_ms, r.timings.voxel_ms + r.timings.verify_ms);
}

TEST(Localizer, AVoxelizedQueryGivesTheSamePoseAsTheRawOne) {
  // A vehicle may send its local cloud already voxelized with the map's grid (protocol flag
  // bit 1): the voxel stage is then skipped and the answer must not change.
  const LocalizerConfig c = config();
  const PointCloud map_cloud = pole_street(true);
  const Localizer localizer(c, extract_segments(map_cloud, Eigen::Vector3f(25, 0, 2), c.segmentation));
  const Pose3d T = T_query_map();
  const PointCloud query = transformed(map_cloud, T);
  const Eigen::Vector3f sensor = T.cast<float>() * Eigen::Vector3f(25, 0, 2);
  const LocalizationResult raw = localizer.localize(query, sensor);
  const PointCloud voxels = voxel_filter(query, c.segmentation.voxel);
  ASSERT_LT(voxels.size(), query.size() / 2);
  const LocalizationResult vox = localizer.localize(voxels, sensor, CloudKind::kVoxelized);
  ASSERT_TRUE(raw.localized()) << raw.reason;
  ASSERT_TRUE(vox.localized()) << vox.reason;
  EXPECT_EQ(vox.query_segments, raw.query_segments);
  EXPECT_LT((vox.T_map_query.translation() - raw.T_map_query.translation()).norm(), 1e-4);
  EXPECT_EQ(vox.timings.voxel_ms, 0.0);
  // Sending voxels without saying so re-voxelizes centroids: most voxels hold one point, < 2.
  EXPECT_FALSE(localizer.localize(voxels, sensor).localized());
}

TEST(Localizer, RefusesAStreetOfIdenticalPolesAsAmbiguous) {
  const LocalizerConfig c = config();
  const PointCloud map_cloud = pole_street(false);
  const Localizer localizer(c, extract_segments(map_cloud, Eigen::Vector3f(25, 0, 2), c.segmentation));
  ASSERT_EQ(localizer.targets().size(), 10u);
  const Pose3d T = T_query_map();
  const LocalizationResult r = localizer.localize(transformed(map_cloud, T), Eigen::Vector3f::Zero());
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kAmbiguous) << r.reason;
  EXPECT_GE(r.hypotheses, 2u);
}

// A prior decides where the answer may lie, not which evidence counts: on a street of
// identical poles 6 m apart the pose one pole along, just outside a narrow prior, explains the
// query as well (retrieval under a prior never makes it a hypothesis; the support beside the
// pose finds it). A fair prior is refused as ambiguous; a prior one pole off, which used to be
// answered one pole off (a wrong prior become a confident fix), is refused the same way. A prior
// 20 m off the street leaves no pose at all.
TEST(Localizer, APriorDoesNotSettleLookAlikesJustBeyondIt) {
  const LocalizerConfig c = config();
  const PointCloud map_cloud = pole_street(false);
  const Localizer localizer(c, extract_segments(map_cloud, Eigen::Vector3f(25, 0, 2), c.segmentation));
  const Pose3d T = T_query_map();
  const PointCloud query = transformed(map_cloud, T);
  const Eigen::Vector3f sensor = T.cast<float>() * Eigen::Vector3f(25, 0, 2);
  PosePrior prior;
  prior.T_map_query = T.inverse();
  prior.T_map_query.translation() += Eigen::Vector3d(0.8, -0.5, 0.0);  // a fair guess
  prior.radius_m = 2.0;
  prior.max_rotation_deg = 3.0;
  const LocalizationResult fair = localizer.localize(query, sensor, CloudKind::kRaw, &prior);
  EXPECT_FALSE(fair.localized()) << to_string(fair.method) << " support " << fair.support << " runner-up "
                                 << fair.runner_up_support << " inliers " << fair.inliers.size() << " hyp "
                                 << fair.hypotheses;
  EXPECT_EQ(fair.refusal, Refusal::kAmbiguous) << fair.reason;
  EXPECT_NE(fair.reason.find("within the prior"), std::string::npos) << fair.reason;

  prior.T_map_query = T.inverse();
  prior.T_map_query.translation() += Eigen::Vector3d(6.0, 0.0, 0.0);  // one pole along the street
  prior.radius_m = 3.0;
  const LocalizationResult off = localizer.localize(query, sensor, CloudKind::kRaw, &prior);
  EXPECT_FALSE(off.localized()) << "answered " << (off.T_map_query * T).translation().norm() << " m off";
  EXPECT_EQ(off.refusal, Refusal::kAmbiguous) << off.reason;

  prior.T_map_query.translation() += Eigen::Vector3d(0.0, 20.0, 0.0);  // beside the street
  EXPECT_FALSE(localizer.localize(query, sensor, CloudKind::kRaw, &prior).localized());
  prior.radius_m = 0.0;
  EXPECT_THROW(localizer.localize(query, sensor, CloudKind::kRaw, &prior), std::invalid_argument);
}

// Two copies of one street 100 m apart: globally the query is ambiguous; a prior around the
// first copy narrows retrieval to it and returns it, never the look-alike outside the prior; a
// prior around neither returns nothing (typed refusals say why).
TEST(Localizer, ALookAlikeOutsideThePriorIsNeverReturned) {
  const LocalizerConfig c = config();
  const PointCloud street = pole_street(true);
  Pose3d shift = Pose3d::Identity();
  shift.translation() << 100.0, 0.0, 0.0;
  PointCloud map_cloud = street;
  const PointCloud copy = transformed(street, shift);
  map_cloud.insert(map_cloud.end(), copy.begin(), copy.end());
  const Localizer localizer(c, extract_segments(map_cloud, Eigen::Vector3f(75, 0, 2), c.segmentation));
  const Pose3d T = T_query_map();
  const PointCloud query = transformed(street, T);
  const Eigen::Vector3f sensor = T.cast<float>() * Eigen::Vector3f(25, 0, 2);
  const LocalizationResult global = localizer.localize(query, sensor);
  EXPECT_FALSE(global.localized());
  EXPECT_EQ(global.refusal, Refusal::kAmbiguous) << global.reason;

  PosePrior prior;
  prior.T_map_query = T.inverse();
  prior.T_map_query.translation() += Eigen::Vector3d(1.5, 1.0, 0.0);
  prior.radius_m = 5.0;
  prior.max_rotation_deg = 5.0;
  const LocalizationResult near_a = localizer.localize(query, sensor, CloudKind::kRaw, &prior);
  ASSERT_TRUE(near_a.localized()) << near_a.reason;
  EXPECT_EQ(near_a.refusal, Refusal::kNone);
  EXPECT_LT((near_a.T_map_query * T).translation().norm(), 0.05) << "the copy inside the prior";
  EXPECT_LT(near_a.candidates, global.candidates) << "retrieval narrowed to the prior";

  prior.T_map_query.translation() += Eigen::Vector3d(0.0, 200.0, 0.0);  // beside both copies
  const LocalizationResult neither = localizer.localize(query, sensor, CloudKind::kRaw, &prior);
  EXPECT_FALSE(neither.localized());
  EXPECT_TRUE(neither.refusal == Refusal::kNoConsistentMatches || neither.refusal == Refusal::kOutsidePrior ||
              neither.refusal == Refusal::kTooFewSegments)
      << to_string(neither.refusal);
}

// The floors a prior may lower (LocalizerConfig::*_with_prior) apply with a prior only.
TEST(Localizer, FloorsWithAPriorApplyOnlyWithAPrior) {
  LocalizerConfig c = config();
  c.min_support = 40;  // more than the street's segments: refused without a prior
  c.min_support_with_prior = 6;
  const PointCloud street = pole_street(true);
  const Localizer localizer(c, extract_segments(street, Eigen::Vector3f(25, 0, 2), c.segmentation));
  const Pose3d T = T_query_map();
  const PointCloud query = transformed(street, T);
  const Eigen::Vector3f sensor = T.cast<float>() * Eigen::Vector3f(25, 0, 2);
  const LocalizationResult global = localizer.localize(query, sensor);
  EXPECT_EQ(global.refusal, Refusal::kLowSupport) << global.reason;
  PosePrior prior;
  prior.T_map_query = T.inverse();
  prior.radius_m = 3.0;
  const LocalizationResult with_prior = localizer.localize(query, sensor, CloudKind::kRaw, &prior);
  EXPECT_TRUE(with_prior.localized()) << with_prior.reason;
  c.min_support_with_prior = 3;  // below verification.min_inliers
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

TEST(Localizer, RefusesEmptyAndNonFiniteQueriesWithAReason) {
  const LocalizerConfig c = config();
  const Localizer localizer(c, extract_segments(pole_street(true), Eigen::Vector3f::Zero(), c.segmentation));
  LocalizationResult r = localizer.localize(PointCloud{}, Eigen::Vector3f::Zero());
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kTooFewSegments) << r.reason;
  EXPECT_FALSE(r.reason.empty());
  PointCloud nan_cloud(1000, Point{NAN, 0.f, 0.f, 0.f});
  r = localizer.localize(nan_cloud, Eigen::Vector3f::Zero());
  EXPECT_FALSE(r.localized());
  EXPECT_EQ(r.refusal, Refusal::kTooFewSegments) << r.reason;
}

TEST(Localizer, RejectsInvalidConfigurationAtConstruction) {
  LocalizerConfig c = config();
  c.min_support = 2;  // below verification.min_inliers
  EXPECT_THROW(Localizer(c, Segments{}), std::invalid_argument);
  c = config();
  c.matcher.type = MatcherType::kRandomForest;  // without a classifier
  EXPECT_THROW(Localizer(c, Segments{}), std::invalid_argument);
  c = config();
  c.max_refine_rmse_voxels = -1.f;
  EXPECT_THROW(Localizer(c, Segments{}), std::invalid_argument);
  c.max_refine_rmse_voxels = NAN;
  EXPECT_THROW(Localizer(c, Segments{}), std::invalid_argument);
  c.max_refine_rmse_voxels = 0.f;  // off
  EXPECT_NO_THROW(Localizer(c, Segments{}));
}

}  // namespace
}  // namespace segmatch
