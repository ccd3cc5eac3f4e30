// The correlative search over a wide prior (correlative_search.h): known answers on the
// generated street (a prior 14 m and 6 degrees off comes back within a cell and a step), a
// brute-force oracle of its score, a street of identical poles (its peaks a pole spacing apart,
// scored alike: the ambiguity the localizer refuses), and the search's bounds.
#include "segmatch/core/localization/correlative_search.h"
#include "support/street_scene.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <vector>

namespace segmatch {
namespace {

using test::pole_street;
using test::transformed;

constexpr double kDeg = M_PI / 180.0;
constexpr double kWindowM = 40.0;  // RegistrationConfig::window_m

Pose3d yaw_about(const Eigen::Vector3d& at, double yaw_deg, const Eigen::Vector3d& shift) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = at - T.linear() * at + shift;
  return T;
}

// The vehicle's frame: the map turned 40 degrees and moved; the sensor mid-street.
struct World {
  PointCloud map;
  Pose3d T_map_query = yaw_about(Eigen::Vector3d::Zero(), 40.0, Eigen::Vector3d(-7.0, 12.0, 0.0));
  Eigen::Vector3d sensor_map{27.0, 0.0, 1.8};
  // objects: the street with its objects and platforms (whose tops hold the height), or poles alone
  explicit World(bool objects) : map(objects ? test::street_with_platforms() : pole_street(false)) {}
  PointCloud query() const { return transformed(map, T_map_query.inverse()); }
  Eigen::Vector3d sensor_query() const { return T_map_query.inverse() * sensor_map; }
  // A prior whose sensor is `shift` and `turn_deg` off the truth.
  Pose3d prior(const Eigen::Vector3d& shift, double turn_deg) const {
    return yaw_about(sensor_map, turn_deg, shift) * T_map_query;
  }
};

double sensor_error_m(const Pose3d& T, const World& w) {
  return (T * w.sensor_query() - w.sensor_map).head<2>().norm();
}
double heading_error_deg(const Pose3d& T, const World& w) {
  return Eigen::AngleAxisd(T.linear() * w.T_map_query.linear().transpose()).angle() / kDeg;
}

TEST(CorrelativeSearch, AWidePriorComesBackWithinACellAndAStep) {
  const World w(true);
  CorrelativeSearchConfig c;
  for (const auto& [shift, turn] :
       {std::pair{Eigen::Vector3d(14.0, -3.0, 0.0), 6.0}, {Eigen::Vector3d(-8.5, 9.0, 0.0), -4.0}}) {
    const Pose3d prior = w.prior(shift, turn);
    ASSERT_GT(sensor_error_m(prior, w), 8.0);
    const std::vector<SearchCandidate> peaks =
        correlative_search(w.query(), w.map, prior, w.sensor_query(), 20.0, 10.0, kWindowM, c);
    ASSERT_FALSE(peaks.empty());
    EXPECT_LE(sensor_error_m(peaks.front().T_map_query, w), c.resolution_m) << shift.transpose();
    EXPECT_LE(heading_error_deg(peaks.front().T_map_query, w), c.angle_step_deg) << shift.transpose();
    EXPECT_GT(peaks.front().score, 0.8) << "the query lies on the map there";
    for (size_t i = 1; i < peaks.size(); ++i) {
      EXPECT_LE(peaks[i].score, peaks[i - 1].score) << "best first";
      EXPECT_GE((peaks[i].T_map_query * w.sensor_query() - peaks.front().T_map_query * w.sensor_query()).norm(),
                c.min_separation_m - 1e-6)
          << "distinct peaks";
    }
  }
}

// Brute-force oracle: the same score written plainly (occupied cells in a std::set, the query's
// one point per cell in a std::map), every heading and cell of the prior tried. The search's best
// peak must score what the oracle's best scores.
double oracle_best(const PointCloud& query, const PointCloud& map, const Pose3d& prior, const Eigen::Vector3d& sensor,
                   double radius_m, double tolerance_deg, const CorrelativeSearchConfig& c) {
  const double cell = c.resolution_m;
  const Eigen::Vector3d centre = prior * sensor;
  const Eigen::Vector2d origin = centre.head<2>() - Eigen::Vector2d::Constant(radius_m + kWindowM + 2.0 * cell);
  auto cell_of = [&](const Eigen::Vector2d& p) {
    return std::pair<long, long>{static_cast<long>(std::floor((p.x() - origin.x()) / cell)),
                                 static_cast<long>(std::floor((p.y() - origin.y()) / cell))};
  };
  std::set<std::pair<long, long>> occupied;
  for (const Point& p : map) occupied.insert(cell_of(p.xyz().cast<double>().head<2>()));
  std::map<std::pair<long, long>, Eigen::Vector3d> first;  // the first query point of each cell
  std::vector<Eigen::Vector3d> offsets;
  for (const Point& p : query) {
    const Eigen::Vector3d d = p.xyz().cast<double>() - sensor;
    if (d.head<2>().norm() > kWindowM) continue;
    const std::pair<long, long> k{static_cast<long>(std::floor(d.x() / cell)),
                                  static_cast<long>(std::floor(d.y() / cell))};
    if (first.emplace(k, d).second) offsets.push_back(d);
  }
  EXPECT_LE(offsets.size(), static_cast<size_t>(c.max_query_points)) << "the oracle does not thin";
  auto value = [&](long x, long y) {
    double v = 0.0;
    for (long dx = -2; dx <= 2; ++dx)
      for (long dy = -2; dy <= 2; ++dy)
        if (occupied.count({x + dx, y + dy})) v = std::max(v, std::exp(-0.5 * double(dx * dx + dy * dy)));
    return v;
  };
  const int steps = static_cast<int>(std::floor(radius_m / cell)),
            turns = static_cast<int>(std::floor(tolerance_deg / c.angle_step_deg));
  double best = 0.0;
  for (int h = -turns; h <= turns; ++h) {
    const Eigen::Matrix3d R =
        Eigen::AngleAxisd(h * c.angle_step_deg * kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix() * prior.linear();
    for (int dx = -steps; dx <= steps; ++dx)
      for (int dy = -steps; dy <= steps; ++dy) {
        if (dx * dx + dy * dy > steps * steps) continue;
        double sum = 0.0;
        for (const Eigen::Vector3d& o : offsets) {
          const auto [x, y] = cell_of(centre.head<2>() + (R * o).head<2>());
          sum += value(x + dx, y + dy);
        }
        best = std::max(best, sum / static_cast<double>(offsets.size()));
      }
  }
  return best;
}

TEST(CorrelativeSearch, ItsBestPeakScoresWhatABruteForceOracleFinds) {
  const World w(true);
  CorrelativeSearchConfig c;
  c.max_query_points = 100000;  // no thinning: the oracle keeps every cell's point
  for (const auto& [shift, turn] :
       {std::pair{Eigen::Vector3d(3.0, 2.0, 0.0), 2.0}, {Eigen::Vector3d(-1.5, -2.5, 0.0), -1.0}}) {
    const Pose3d prior = w.prior(shift, turn);
    const std::vector<SearchCandidate> peaks =
        correlative_search(w.query(), w.map, prior, w.sensor_query(), 4.0, 3.0, kWindowM, c);
    ASSERT_FALSE(peaks.empty());
    EXPECT_NEAR(peaks.front().score, oracle_best(w.query(), w.map, prior, w.sensor_query(), 4.0, 3.0, c), 1e-6);
    EXPECT_GT(peaks.front().score, 0.75) << "near the truth the query lies on the map (less a sub-cell offset)";
  }
}

TEST(CorrelativeSearch, AStreetOfIdenticalPolesHasPeaksAPoleSpacingApart) {
  const World w(false);  // poles every 6 m and nothing else
  const Pose3d prior = w.prior(Eigen::Vector3d(2.0, 1.0, 0.0), 0.0);
  const std::vector<SearchCandidate> peaks =
      correlative_search(w.query(), w.map, prior, w.sensor_query(), 15.0, 5.0, kWindowM, {});
  ASSERT_GE(peaks.size(), 2u);
  EXPECT_NEAR(peaks[1].score, peaks[0].score, 0.2 * peaks[0].score) << "look-alikes score alike";
  const Eigen::Vector3d a = peaks[0].T_map_query * w.sensor_query(), b = peaks[1].T_map_query * w.sensor_query();
  EXPECT_NEAR(std::fmod(std::abs(a.x() - b.x()) + 0.5, 6.0), 0.5, 1.1) << "a multiple of the pole spacing apart";
}

TEST(CorrelativeSearch, StaysWithinThePriorAndNeedsPoints) {
  const World w(true);
  const Pose3d prior = w.prior(Eigen::Vector3d(14.0, -3.0, 0.0), 6.0);
  // The truth is 14.3 m and 6 degrees away, outside a 5 m, 2 degree prior: whatever the peaks
  // are, they stay inside it.
  for (const SearchCandidate& p :
       correlative_search(w.query(), w.map, prior, w.sensor_query(), 5.0, 2.0, kWindowM, {})) {
    EXPECT_LE((p.T_map_query * w.sensor_query() - prior * w.sensor_query()).head<2>().norm(), 5.0 + 1e-9);
    EXPECT_LE(Eigen::AngleAxisd(p.T_map_query.linear() * prior.linear().transpose()).angle() / kDeg, 2.0 + 1e-9);
  }
  EXPECT_TRUE(correlative_search({}, w.map, prior, w.sensor_query(), 5.0, 2.0, kWindowM, {}).empty());
  EXPECT_TRUE(correlative_search(w.query(), {}, prior, w.sensor_query(), 5.0, 2.0, kWindowM, {}).empty());
}

// In the localizer: a prior 13 m and 4 degrees off, radius 20 m (a GNSS fix), is answered by
// registration from the search's peak; with the search off, registration refuses the prior as too
// wide (segment matching may still answer).
TEST(CorrelativeSearch, TheLocalizerAnswersAWidePriorByRegistrationFromAPeak) {
  const World w(true);
  LocalizerConfig c = test::street_localizer_config();
  PosePrior prior;
  prior.T_map_query = w.prior(Eigen::Vector3d(12.0, 5.0, 0.0), 4.0);
  prior.radius_m = 20.0;
  prior.max_rotation_deg = 10.0;
  const Eigen::Vector3f sensor = w.sensor_query().cast<float>();
  {
    const Localizer localizer(c, extract_segments(w.map, w.sensor_map.cast<float>(), c.segmentation));
    const LocalizationResult r = localizer.localize(w.query(), sensor, CloudKind::kRaw, &prior);
    ASSERT_TRUE(r.localized()) << r.reason;
    EXPECT_EQ(r.method, LocalizationMethod::kRegistration) << r.registration_reason;
    EXPECT_LT(sensor_error_m(r.T_map_query, w), 0.05);
    EXPECT_LT(heading_error_deg(r.T_map_query, w), 0.1);
  }
  c.search.enabled = false;
  const Localizer without(c, extract_segments(w.map, w.sensor_map.cast<float>(), c.segmentation));
  const LocalizationResult r = without.localize(w.query(), sensor, CloudKind::kRaw, &prior);
  EXPECT_EQ(r.registration_refusal, RegistrationRefusal::kWidePrior) << r.registration_reason;
  EXPECT_NE(r.method, LocalizationMethod::kRegistration);
}

// Two copies of the street 30 m apart, both inside a wide prior: registrations from both peaks
// pass, and the localizer refuses to pick one.
TEST(CorrelativeSearch, TwoLookAlikesInsideTheWidePriorAreAmbiguous) {
  const World w(true);
  LocalizerConfig c = test::street_localizer_config();
  Pose3d shift = Pose3d::Identity();
  shift.translation() << 0.0, 30.0, 0.0;
  PointCloud map = w.map;
  const PointCloud copy = transformed(w.map, shift);
  map.insert(map.end(), copy.begin(), copy.end());
  const Localizer localizer(c, extract_segments(map, Eigen::Vector3f(27.f, 15.f, 1.8f), c.segmentation));
  PosePrior prior;
  prior.T_map_query = w.prior(Eigen::Vector3d(0.0, 15.0, 0.0), 0.0);  // between the copies
  prior.radius_m = 25.0;
  prior.max_rotation_deg = 5.0;
  const LocalizationResult r = localizer.localize(w.query(), w.sensor_query().cast<float>(), CloudKind::kRaw, &prior);
  EXPECT_NE(r.method == LocalizationMethod::kRegistration && r.localized(), true) << "registration picked a copy";
  EXPECT_EQ(r.registration_refusal, RegistrationRefusal::kAmbiguous) << r.registration_reason;
}

TEST(CorrelativeSearch, ConfigRefusesBadValuesByName) {
  CorrelativeSearchConfig c;
  EXPECT_NO_THROW(c.validate());
  c.resolution_m = 0.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.candidates = 0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  c = {};
  c.angle_step_deg = std::nanf("");
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
