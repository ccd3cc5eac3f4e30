// Cold start (place_recognition.h, Localizer::recognize_place): Scan Context descriptors of a
// generated street, the places of a map along its trajectory, and a query without a prior
// localized by the place it resembles, or refused.
#include "segmatch/core/localization/place_recognition.h"
#include "segmatch/core/localization/localizer.h"
#include "support/street_scene.h"
#include "support/validation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <random>
#include <stdexcept>

namespace segmatch {
namespace {

using test::transformed;

constexpr double kDeg = M_PI / 180.0;

Pose3d yaw_about(double yaw_rad, const Eigen::Vector3d& centre) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = centre - T.linear() * centre;
  return T;
}

// The map: the street with its ground, driven along y = 0 heading +x, the sensor 2 m up.
struct MappedStreet {
  PointCloud layer = test::with_ground(test::street_with_platforms());
  std::shared_ptr<const MapSurfaces> surfaces = std::make_shared<test::InMemorySurfaces>(layer);
  std::vector<Pose3d> trajectory = [] {
    std::vector<Pose3d> t;
    for (double x = 0.0; x <= 55.0; x += 1.0) {
      Pose3d T = Pose3d::Identity();
      T.translation() = Eigen::Vector3d(x, 0.0, 2.0);
      t.push_back(T);
    }
    return t;
  }();
  PlaceIndex places(const PlaceRecognitionConfig& config = {}) const {
    return build_place_index(
        trajectory, [this](const Eigen::Vector3d& c, double r) { return surfaces->near(c, r); }, config);
  }
  // The vehicle's odometry frame: map points into it.
  Pose3d T_query = [] {
    Pose3d T = Pose3d::Identity();
    T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(-12.0, 30.0, 0.5);
    return T;
  }();
};

// The street's localizer, its ground removed: the wide-prior search compares what stands on it.
LocalizerConfig config_with_ground() {
  LocalizerConfig c = test::street_localizer_config();
  c.segmentation.ground = GroundConfig{};
  return c;
}

TEST(PlaceRecognition, TheDescriptorTurnsWithTheCloudBySectors) {
  const MappedStreet m;
  const PlaceRecognitionConfig c;
  const Eigen::Vector3d centre(25.0, 0.0, 2.0);
  const PlaceDescriptor place = describe_place(m.layer, centre, 0.0, c);
  ASSERT_GT(place.occupied(), 50u);
  for (int k : {0, 5, 17, 42}) {
    // The cloud turned by k sectors about the centre: its bins move by k, nothing else changes.
    const double turn = k * 2.0 * M_PI / c.sectors + 0.5 * kDeg;  // half a degree into the sector, off its edge
    const PlaceDescriptor turned = describe_place(transformed(m.layer, yaw_about(turn, centre)), centre, 0.0, c);
    const PlaceDistance d = place_distance(turned, place);
    EXPECT_LT(d.distance, 0.05) << "k " << k;
    EXPECT_EQ(d.shift_sectors, (c.sectors - k) % c.sectors) << "k " << k;
  }
  PlaceDescriptor other = place;
  other.sectors = 30;
  EXPECT_THROW(place_distance(place, other), std::invalid_argument);
}

// Scan Context's distance as its definition reads (Kim & Kim, eq. 5), in double, per shift k
// (query sector j against place sector j + k): 1 - the mean cosine of the columns occupied in
// both, 1 where fewer than a sector in six are. The brute-force oracle of place_distance.
std::vector<double> distances_by_definition(const PlaceDescriptor& q, const PlaceDescriptor& p) {
  const int R = q.rings, S = q.sectors;
  auto cell = [S](const PlaceDescriptor& d, int r, int s) { return double(d.cells[size_t(r) * S + s]); };
  std::vector<double> out(size_t(S), 1.0);
  for (int k = 0; k < S; ++k) {
    double sum = 0.0;
    int shared = 0;
    for (int j = 0; j < S; ++j) {
      const int m = (j + k) % S;
      double ab = 0.0, aa = 0.0, bb = 0.0;
      for (int r = 0; r < R; ++r) {
        ab += cell(q, r, j) * cell(p, r, m);
        aa += cell(q, r, j) * cell(q, r, j);
        bb += cell(p, r, m) * cell(p, r, m);
      }
      if (aa <= 0.0 || bb <= 0.0) continue;
      sum += ab / std::sqrt(aa * bb);
      ++shared;
    }
    if (shared >= std::max(1, S / 6)) out[size_t(k)] = 1.0 - sum / shared;
  }
  return out;
}

TEST(PlaceRecognition, TheDistanceIsScanContextsDefinition) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> height(0.8f, 3.0f), u(0.f, 1.f);
  for (const auto& [rings, sectors] : {std::pair{20, 60}, std::pair{7, 13}, std::pair{3, 720}})
    for (double empty : {0.0, 0.5, 0.9, 0.97, 1.0}) {
      auto random_descriptor = [&, rings = rings, sectors = sectors] {
        PlaceDescriptor d;
        d.rings = rings;
        d.sectors = sectors;
        for (int i = 0; i < rings * sectors; ++i) d.cells.push_back(u(rng) < empty ? 0.f : height(rng));
        return d;
      };
      const PlaceDescriptor a = random_descriptor(), b = random_descriptor();
      const std::vector<double> slow = distances_by_definition(a, b);
      const double best = *std::min_element(slow.begin(), slow.end());
      const PlaceDistance fast = place_distance(a, b);
      EXPECT_NEAR(fast.distance, best, 1e-5) << rings << "x" << sectors << " empty " << empty;
      // Its shift is the best one, or one the oracle finds as good to float precision.
      if (best < 1.0) {
        EXPECT_NEAR(slow[size_t(fast.shift_sectors)], best, 1e-5) << rings << "x" << sectors;
      }
    }
  PlaceDescriptor cut;
  cut.rings = 20;
  cut.sectors = 60;
  cut.cells.assign(20 * 59, 1.f);
  EXPECT_THROW(place_columns(cut), std::invalid_argument);
}

// SLAM keyframes lie metres apart: places come every place_spacing_m between them all the same,
// but not across a gap no street is driven straight (kMaxInterpolatedGapM).
TEST(PlaceRecognition, PlacesFillTheGapsBetweenSparseKeyframes) {
  const MappedStreet m;
  auto near = [&m](const Eigen::Vector3d& c, double r) { return m.surfaces->near(c, r); };
  auto at = [](double x) {
    Pose3d T = Pose3d::Identity();
    T.translation() = Eigen::Vector3d(x, 0.0, 2.0);
    return T;
  };
  PlaceRecognitionConfig c;
  c.place_spacing_m = 2.0f;
  const PlaceIndex sparse = build_place_index({at(0.0), at(10.0), at(20.0), at(30.0), at(40.0), at(50.0)}, near, c);
  EXPECT_EQ(sparse.size(), 26u * 5u);  // a stop every 2 m of the 50, as from a pose every metre
  for (size_t i = 5; i < sparse.size(); i += 5)
    EXPECT_NEAR(sparse.pose(i).translation().x() - sparse.pose(i - 5).translation().x(), 2.0, 1e-9) << i;
  const PlaceIndex jump = build_place_index({at(0.0), at(150.0)}, near, c);
  EXPECT_EQ(jump.size(), 2u * 5u);
}

TEST(PlaceRecognition, TheIndexFindsThePlaceAndTheHeadingOfAQueryFromAnotherLane) {
  const MappedStreet m;
  const PlaceIndex index = m.places();
  // Five places a stop (the trajectory's and two lanes either side), a stop every metre of the 55.
  EXPECT_EQ(index.size(), 56u * 5u);
  const Eigen::Vector3d truth_map(31.4, 1.3, 2.0);
  const Eigen::Vector3d sensor_query = m.T_query * truth_map;
  const PointCloud scan = crop_cylinder(transformed(m.layer, m.T_query), sensor_query, 40.0);
  const std::vector<PlaceCandidate> found =
      index.query(describe_place(scan, sensor_query, 0.0, index.config()), sensor_query);
  ASSERT_FALSE(found.empty());
  const PlaceCandidate& best = found.front();
  EXPECT_LT((best.T_map_query * sensor_query - truth_map).head<2>().norm(), 1.5);
  const double heading_error_deg =
      std::abs(std::remainder(yaw_of(best.T_map_query) - yaw_of(m.T_query.inverse()), 2.0 * M_PI)) / kDeg;
  EXPECT_LT(heading_error_deg, 6.1);                                       // a sector
  EXPECT_NEAR((best.T_map_query * sensor_query).z(), truth_map.z(), 0.2);  // ground on ground
  for (size_t i = 1; i < found.size(); ++i) EXPECT_GE(found[i].distance, found[i - 1].distance);
}

TEST(PlaceRecognition, ColdStartLocalizesAScanWithoutAPriorByThePlaceItShows) {
  const MappedStreet m;
  const LocalizerConfig config = config_with_ground();
  const Segments targets = extract_segments(m.layer, Eigen::Vector3f(25.f, 0.f, 2.f), config.segmentation);
  const Localizer localizer(config, targets, nullptr, nullptr, m.surfaces,
                            ready_places(std::make_shared<const PlaceIndex>(m.places(config.places))));
  const Eigen::Vector3d truth_map(22.6, -0.8, 2.0);
  const Eigen::Vector3d s = m.T_query * truth_map;
  const PointCloud scan = crop_cylinder(transformed(m.layer, m.T_query), s, 35.0);
  LocalizationResult refused;  // as segment matching leaves it: refused, its query segments kept
  refused.refusal = Refusal::kNoConsistentMatches;
  refused.reason = "segment matching refused it";
  refused.query = extract_segments(scan, s.cast<float>(), config.segmentation);
  const LocalizationResult r = localizer.recognize_place(refused, scan, scan, s.cast<float>());
  ASSERT_TRUE(r.localized()) << r.reason;
  EXPECT_EQ(r.method, LocalizationMethod::kPlaces);
  EXPECT_LT((r.T_map_query * s - truth_map).norm(), 0.1);
  EXPECT_GE(r.refine_fitness, config.places.min_fitness);
  EXPECT_TRUE(r.covariance.allFinite());
  EXPECT_GT(r.covariance.trace(), 0.0);
}

// crop_elevation keeps what a sensor with that vertical field of view sees: known answers.
TEST(PlaceRecognition, CropElevationKeepsThePointsWithinTheBand) {
  const Eigen::Vector3f sensor(1.f, 2.f, 2.f);
  PointCloud points;
  for (double deg : {-30.0, -10.0, -1.0, 0.0, 1.9, 2.1, 15.0, 80.0}) {
    const double d = 10.0;
    points.push_back(Point{1.f + static_cast<float>(d), 2.f, 2.f + static_cast<float>(d * std::tan(deg * kDeg)), 0.f});
  }
  const PointCloud kept = crop_elevation(points, sensor, -15.0, 2.0);
  ASSERT_EQ(kept.size(), 4u);  // -10, -1, 0, 1.9
  EXPECT_NEAR(kept.front().z, 2.f + 10.f * std::tan(-10.0 * kDeg), 1e-5);
  EXPECT_EQ(crop_elevation(points, sensor, -90.0, 90.0).size(), points.size());
}

// A map whose sensor looked no higher than +2 degrees (an HDL-64E on a car: its layer holds what
// stands within about 3.4 m of the ground, seen from up to 40 m) and a scan from a sensor that
// sees whole facades (a VLP-16 to +15): the scan's points above what the map's sensor saw have no
// counterpart. Kept to the map's elevations (PlaceRecognitionConfig::map_elevation_*), the scan
// localizes; taken whole, it fits worse.
TEST(PlaceRecognition, ColdStartKeepsTheScanToWhatTheMapsSensorSaw) {
  const MappedStreet m;
  PointCloud street = m.layer;  // with facades 12 m tall on either side
  for (const float y : {-17.f, 18.f})
    for (float x = -8.f; x <= 58.f; x += 0.1f)
      for (float z = 0.f; z <= 12.f; z += 0.1f) street.push_back(Point{x, y, z, 0.f});
  const double reach_m = 2.0 + std::tan(2.0 * kDeg) * 40.0;
  PointCloud low;
  for (const Point& p : street)
    if (p.z <= reach_m) low.push_back(p);
  const auto surfaces = std::make_shared<test::InMemorySurfaces>(low);
  LocalizerConfig config = config_with_ground();
  const Segments targets = extract_segments(low, Eigen::Vector3f(25.f, 0.f, 2.f), config.segmentation);
  const Eigen::Vector3d truth_map(22.6, -0.8, 2.0);
  const Eigen::Vector3d s = m.T_query * truth_map;
  const PointCloud scan = crop_cylinder(transformed(street, m.T_query), s, 35.0);
  LocalizationResult refused;
  refused.refusal = Refusal::kNoConsistentMatches;
  refused.reason = "segment matching refused it";
  refused.query = extract_segments(scan, s.cast<float>(), config.segmentation);
  auto cold_start = [&](const LocalizerConfig& c) {
    auto index = std::make_shared<const PlaceIndex>(build_place_index(
        m.trajectory, [&](const Eigen::Vector3d& centre, double r) { return surfaces->near(centre, r); }, c.places));
    const Localizer localizer(c, targets, nullptr, nullptr, surfaces, ready_places(index));
    return localizer.recognize_place(refused, scan, scan, s.cast<float>());
  };
  const LocalizationResult whole = cold_start(config);
  config.places.map_elevation_min_deg = -25.0f;
  config.places.map_elevation_max_deg = 2.0f;
  const LocalizationResult kept = cold_start(config);
  ASSERT_TRUE(kept.localized()) << kept.reason;
  EXPECT_LT((kept.T_map_query * s - truth_map).norm(), 0.1);
  EXPECT_FALSE(whole.localized() && whole.refine_fitness >= kept.refine_fitness)
      << "the whole scan fitted " << whole.refine_fitness << ", the kept one " << kept.refine_fitness;
}

TEST(PlaceRecognition, AScanOfAnUnmappedStreetIsRefusedWithTheReason) {
  const MappedStreet m;
  const LocalizerConfig config = config_with_ground();
  const Segments targets = extract_segments(m.layer, Eigen::Vector3f(25.f, 0.f, 2.f), config.segmentation);
  const Localizer localizer(config, targets, nullptr, nullptr, m.surfaces,
                            ready_places(std::make_shared<const PlaceIndex>(m.places(config.places))));
  // Another street: the poles on the other side, other objects, its own ground.
  PointCloud elsewhere;
  for (int i = 0; i < 10; ++i) test::add_cylinder(elsewhere, 5.f * i + 2.f, -5.f, 0.2f, 6.f);
  test::add_box(elsewhere, 10.f, 6.f, 12.f, 3.f, 3.f);
  test::add_box(elsewhere, 30.f, -12.f, 3.f, 8.f, 2.f);
  elsewhere = test::with_ground(elsewhere);
  const Eigen::Vector3d s(25.0, 0.0, 2.0);
  LocalizationResult refused;
  refused.refusal = Refusal::kNoConsistentMatches;
  refused.reason = "segment matching refused it";
  const LocalizationResult r = localizer.recognize_place(refused, elsewhere, elsewhere, s.cast<float>());
  EXPECT_FALSE(r.localized());
  EXPECT_NE(r.reason.find("place recognition"), std::string::npos) << r.reason;
  // Without places (an old map, or places.enabled off) the refusal comes back as it was.
  const Localizer without(config, targets, nullptr, nullptr, m.surfaces);
  const LocalizationResult same = without.recognize_place(refused, elsewhere, elsewhere, s.cast<float>());
  EXPECT_EQ(same.refusal, Refusal::kNoConsistentMatches);
  EXPECT_EQ(same.reason, refused.reason);
}

TEST(PlaceRecognition, ABuildStopsWhenCancelledAndAReadyFutureHoldsTheIndex) {
  const MappedStreet m;
  std::atomic<bool> stop{true};
  const PlaceIndex none = build_place_index(
      m.trajectory, [&m](const Eigen::Vector3d& c, double r) { return m.surfaces->near(c, r); },
      PlaceRecognitionConfig{}, &stop);
  EXPECT_EQ(none.size(), 0u);
  const PlacesFuture ready = ready_places(std::make_shared<const PlaceIndex>(m.places()));
  ASSERT_TRUE(ready.valid());
  EXPECT_EQ(ready.get()->size(), 56u * 5u);
  const Localizer without(test::street_localizer_config(), {}, nullptr, nullptr, m.surfaces);
  EXPECT_EQ(without.places(), nullptr);
}

TEST(PlaceRecognition, ConfigRefusesBadValuesByName) {
  auto refused_with = [](const PlaceRecognitionConfig& c, const char* field) {
    return test::validation_message(c).find(field) != std::string::npos;
  };
  PlaceRecognitionConfig c;
  EXPECT_NO_THROW(c.validate());
  c.rings = 1;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.rings"));
  c = {};
  c.shortlist = 5;
  c.candidates = 6;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.candidates"));
  c = {};
  c.shortlist = -1;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.shortlist"));
  c = {};
  c.max_height_m = c.min_height_m;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.max_height_m"));
  c = {};
  c.min_fitness = 1.5f;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.min_fitness"));
  c = {};
  c.lateral_steps = -1;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.lateral_steps"));
  c = {};
  c.map_elevation_min_deg = 5.0f;
  c.map_elevation_max_deg = 2.0f;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.map_elevation_min_deg"));
  c = {};
  c.elevation_excess_deg = -1.0f;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.elevation_excess_deg"));
  c = {};
  c.block_height_m = 0.0f;
  EXPECT_TRUE(refused_with(c, "PlaceRecognitionConfig.block_height_m"));
}

}  // namespace
}  // namespace segmatch
