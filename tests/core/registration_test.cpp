// Registration to the map around a prior (registration.h): known answers on generated scenes,
// the gates (a far prior, a wide prior, a corridor), and the covariance against the spread of
// poses over noise draws.
#include "segmatch/core/localization/registration.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/core/verification/verification.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <cmath>
#include <string>
#include <vector>

namespace segmatch {
namespace {

constexpr double kDeg = M_PI / 180.0;

struct Scene {
  Rng rng;
  PointCloud cloud;
  double noise_m = 0.0;
  explicit Scene(uint64_t seed, double noise = 0.0) : rng(seed), noise_m(noise) {}
  void face(Eigen::Vector3d o, Eigen::Vector3d u, Eigen::Vector3d v, double per_m2) {
    const int n = static_cast<int>(u.norm() * v.norm() * per_m2);
    for (int i = 0; i < n; ++i) {
      Eigen::Vector3d p = o + rng.uniform() * u + rng.uniform() * v;
      if (noise_m > 0) p += Eigen::Vector3d(rng.normal(0, noise_m), rng.normal(0, noise_m), rng.normal(0, noise_m));
      cloud.push_back({static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), 0.f});
    }
  }
  void box(Eigen::Vector3d lo, Eigen::Vector3d size, double per_m2) {
    const Eigen::Vector3d X(size.x(), 0, 0), Y(0, size.y(), 0), Z(0, 0, size.z());
    face(lo, X, Z, per_m2), face(lo + Y, X, Z, per_m2), face(lo, Y, Z, per_m2), face(lo + X, Y, Z, per_m2);
    face(lo + Z, X, Y, per_m2);
  }
};

// A street: facades on both sides with steps,
// parked boxes, a few poles. Map frame = street frame; the sensor at the origin.
PointCloud street(uint64_t seed, double noise_m = 0.0) {
  Scene s(seed, noise_m);
  for (int k = -4; k < 4; ++k) {
    const double x = 10.0 * k, setback = 1.5 * ((k * 7 + 3) % 3);
    s.face({x, 9 + setback, 0}, {10, 0, 0}, {0, 0, 8}, 40);
    s.face({x, -9 - setback, 0}, {10, 0, 0}, {0, 0, 6}, 40);
    s.face({x, 9 + setback, 0}, {0, 1.0 + (k + 4) % 3, 0}, {0, 0, 8}, 40);  // facade steps, both sides
    s.face({x, -9 - setback, 0}, {0, -1.0 - (k + 5) % 3, 0}, {0, 0, 6}, 40);
  }
  s.face({-40, -12, 0}, {80, 0, 0}, {0, 24, 0},
         4);  // ground: it holds z here (car roofs and kerbs do in real segments)
  for (double x : {-25.0, -12.0, 4.0, 17.0, 30.0}) s.box({x, 5.5, 0}, {4.2, 1.8, 1.5}, 20);
  for (double x : {-30.0, -5.0, 11.0, 26.0}) s.box({x, -7.0, 0}, {0.3, 0.3, 5}, 40);
  return s.cloud;
}

// Two parallel walls and nothing else along x: the motion along x is free.
PointCloud corridor(uint64_t seed) {
  Scene s(seed);
  s.face({-40, 4, 0}, {80, 0, 0}, {0, 0, 5}, 40);
  s.face({-40, -4, 0}, {80, 0, 0}, {0, 0, 5}, 40);
  s.face({-40, -4, 5}, {80, 0, 0}, {0, 8, 0}, 20);  // a ceiling: z is held
  return s.cloud;
}

PointCloud transformed(const PointCloud& in, const Pose3d& T) {
  PointCloud out = in;
  for (Point& p : out) {
    const Eigen::Vector3f q = (T * p.xyz().cast<double>()).cast<float>();
    p.x = q.x(), p.y = q.y(), p.z = q.z();
  }
  return out;
}

Pose3d pose(double x, double y, double yaw_deg) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, 0.2);
  return T;
}

double rotation_error_deg(const Pose3d& a, const Pose3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle() / kDeg;
}

// The query frame: the vehicle's odometry frame, T_map_query the truth; the sensor at its origin.
const Pose3d kTruth = pose(3.0, -1.0, 25.0);
const Eigen::Vector3d kSensor(0, 0, 1.8);

RegistrationResult run(const PointCloud& map, const PointCloud& query_map_frame, const Pose3d& prior,
                       double radius_m = 5.0, const RegistrationConfig& config = {},
                       const CovarianceConfig& covariance = {}) {
  return register_to_map(transformed(query_map_frame, kTruth.inverse()), map, prior, kSensor, radius_m, 10.0, 0.15f,
                         config, RefineConfig{}, covariance);
}

TEST(Registration, ConvergesFromAPriorOffByAMetreAndTwoDegrees) {
  const PointCloud map = street(1), query = street(2);  // other samples of the same surfaces
  const RegistrationResult r = run(map, query, pose(1.0, 0.5, 2.0) * kTruth);
  ASSERT_TRUE(r.accepted()) << r.reason;
  EXPECT_LT((r.T_map_query.translation() - kTruth.translation()).norm(), 0.02);
  EXPECT_LT(rotation_error_deg(r.T_map_query, kTruth), 0.1);
  EXPECT_GT(r.fitness, 0.9f);
  EXPECT_TRUE(r.covariance.isApprox(r.covariance.transpose()));
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Matrix6d>(r.covariance).eigenvalues()(0), 0.0) << "positive definite";
}

// A prior on another stretch of the same street (facades, boxes and poles at other places):
// never a fix there, whichever gate stops it.
// The coarse stage on the map thinned to 0.5 m (the default) or at full density reaches the
// same answer: only the fine stage, on every map point, decides it.
TEST(Registration, TheThinnedCoarseStageEndsWhereTheFullOneDoes) {
  const PointCloud map = street(1), query = street(2);
  RegistrationConfig full;
  full.coarse_leaf_m = 0.0f;
  const RegistrationResult thinned = run(map, query, pose(1.0, 0.5, 2.0) * kTruth);
  const RegistrationResult dense = run(map, query, pose(1.0, 0.5, 2.0) * kTruth, 5.0, full);
  ASSERT_TRUE(thinned.accepted()) << thinned.reason;
  ASSERT_TRUE(dense.accepted()) << dense.reason;
  EXPECT_LT((thinned.T_map_query.translation() - dense.T_map_query.translation()).norm(), 0.005);
  EXPECT_LT(rotation_error_deg(thinned.T_map_query, dense.T_map_query), 0.02);
}

TEST(Registration, APriorFiftyMetresOffIsNeverAccepted) {
  const PointCloud map = street(1), query = street(2);
  for (double dx : {-50.0, 50.0, 20.0, -10.0}) {
    const RegistrationResult r = run(map, query, pose(dx, 0.0, 0.0) * kTruth, 10.0);
    EXPECT_FALSE(r.accepted()) << "prior " << dx << " m off: " << r.fitness;
  }
}

TEST(Registration, AWidePriorIsNotAStartingPoint) {
  const RegistrationResult r = run(street(1), street(2), kTruth, 31.0);
  EXPECT_EQ(r.refusal, RegistrationRefusal::kWidePrior);
  EXPECT_NE(r.reason.find("radius"), std::string::npos);
}

TEST(Registration, ACorridorIsReportedDegenerateAlongItsAxis) {
  const RegistrationResult r = run(corridor(1), corridor(2), pose(0.3, 0.2, 1.0) * kTruth);
  EXPECT_EQ(r.refusal, RegistrationRefusal::kDegenerate) << r.reason;
  EXPECT_GT(std::abs(r.weakest_axis.x()), 0.95) << "the weakest axis is the corridor's: " << r.weakest_axis.transpose();
  EXPECT_LT(r.weakest_axis_share, 0.01f);
}

TEST(Registration, TooFewPointsInTheWindow) {
  RegistrationConfig config;
  config.window_m = 1.0f;
  const RegistrationResult r = run(street(1), street(2), kTruth, 5.0, config);
  EXPECT_EQ(r.refusal, RegistrationRefusal::kFewPoints);
}

// The covariance's ICP term against the spread of registered poses over independent noise
// draws of the query (the map noise-free): with scale 1, no floor and independent errors the
// two agree. (The defaults widen it for what real data has and this does not.)
TEST(Registration, CovarianceMatchesTheSpreadOverNoiseDraws) {
  const PointCloud map = street(1);
  std::vector<Eigen::Vector3d> positions;
  Matrix6d reported = Matrix6d::Zero();
  CovarianceConfig icp_only;
  icp_only.scale = 1.0f, icp_only.floor_m = 0.0f, icp_only.floor_deg = 0.0f;
  for (uint64_t seed = 10; seed < 40; ++seed) {
    const RegistrationResult r = run(map, street(seed, 0.05), pose(0.3, 0.2, 1.0) * kTruth, 5.0, {}, icp_only);
    ASSERT_TRUE(r.accepted()) << r.reason;
    positions.push_back(r.T_map_query * kSensor);
    reported += r.covariance / 30.0;
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : positions) mean += p / positions.size();
  Eigen::Matrix3d spread = Eigen::Matrix3d::Zero();
  for (const auto& p : positions) spread += (p - mean) * (p - mean).transpose() / (positions.size() - 1);
  for (int axis = 0; axis < 2; ++axis) {
    const double empirical = std::sqrt(spread(axis, axis)), predicted = std::sqrt(reported(3 + axis, 3 + axis));
    EXPECT_GT(predicted, 0.4 * empirical) << "axis " << axis;
    EXPECT_LT(predicted, 2.5 * empirical) << "axis " << axis;
  }
}

TEST(Registration, TheCovarianceFloorIsAddedOnEveryAxis) {
  const PointCloud map = street(1), query = street(2);
  CovarianceConfig none, floored;
  none.floor_m = none.floor_deg = 0.0f;
  floored.floor_m = 0.1f, floored.floor_deg = 0.5f;
  const RegistrationResult a = run(map, query, kTruth, 5.0, {}, none), b = run(map, query, kTruth, 5.0, {}, floored);
  ASSERT_TRUE(a.accepted() && b.accepted());
  const double rad = 0.5 * kDeg;
  for (int i = 0; i < 6; ++i)
    EXPECT_NEAR(b.covariance(i, i) - a.covariance(i, i), i < 3 ? rad * rad : 0.01, 1e-8) << "axis " << i;
  const bool same_cross_terms = b.covariance.block<3, 3>(0, 3).isApprox(a.covariance.block<3, 3>(0, 3));
  EXPECT_TRUE(same_cross_terms) << "off-diagonal terms unchanged";
}

TEST(Registration, ConfigValidation) {
  RegistrationConfig c;
  EXPECT_NO_THROW(c.validate());
  c.window_m = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.min_axis_share = 0.5f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.min_fitness = 1.5f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.coarse_leaf_m = -0.5f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c.coarse_leaf_m = 0.0f;  // off: the coarse stage on the map at full density
  EXPECT_NO_THROW(c.validate());
  CovarianceConfig v;
  EXPECT_NO_THROW(v.validate());
  v.scale = 0.0f;
  EXPECT_THROW(v.validate(), std::invalid_argument);
  v = {};
  v.floor_m = -1.0f;
  EXPECT_THROW(v.validate(), std::invalid_argument);
}

// The refinement settles as well a few kilometres from the map frame's origin as at it: steps
// are measured where the points are, not at the origin, where a turn of 1e-5 rad is millimetres
// of translation; and a correspondence flipping between two neighbours and back ends the loop.
TEST(Registration, TheFineStageSettlesAsWellFarFromTheMapOrigin) {
  const Pose3d start = pose(0.3, -0.2, 1.0) * kTruth;
  int iterations_at_origin = 0;
  for (const Eigen::Vector3d& offset : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(2500, -1800, 40)}) {
    Pose3d O = Pose3d::Identity();
    O.translation() = offset;
    const PointCloud map = transformed(street(1, 0.02), O);
    const PointCloud query = transformed(street(2, 0.02), kTruth.inverse());
    RefineConfig config;
    config.max_iterations = 50;
    const RefineResult r = refine_alignment(query, map, O * start, config, O * kTruth * kSensor);
    SCOPED_TRACE("offset " + std::to_string(offset.norm()) + " m: " + std::to_string(r.iterations) + " iterations");
    EXPECT_TRUE(r.converged);
    EXPECT_LT(((O * kTruth).translation() - r.T_target_query.translation()).norm(), 0.01);
    EXPECT_LT(rotation_error_deg(r.T_target_query, O * kTruth), 0.05);
    if (offset.isZero()) iterations_at_origin = r.iterations;
    EXPECT_LE(r.iterations, iterations_at_origin + 1);  // steps measured at the origin failed this
  }
}

}  // namespace
}  // namespace segmatch
