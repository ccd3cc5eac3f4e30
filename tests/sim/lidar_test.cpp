// Tests of the LiDAR models and the scan simulation.
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/raycaster.h"
#include "segmatch/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace segmatch::sim {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr uint32_t kGroundLabel = 40;
constexpr uint32_t kBoxLabel = (7u << 16) | 10u;

Scene ground_scene(float half_size = 5000.0f) {
  const float h = half_size;
  return {Primitive::triangle({-h, -h, 0}, {h, -h, 0}, {h, h, 0}, kGroundLabel, 0.3f),
          Primitive::triangle({-h, -h, 0}, {h, h, 0}, {-h, h, 0}, kGroundLabel, 0.3f)};
}

Pose3d pose(double x, double y, double z, double yaw = 0.0) {
  Pose3d T = Pose3d::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

double azimuth(const Point& p) {  // [0, 2 pi)
  double a = std::atan2(p.y, p.x);
  return a < 0 ? a + 2 * kPi : a;
}

double elevation_deg(const Point& p) { return std::atan2(p.z, std::hypot(p.x, p.y)) * 180.0 / kPi; }

bool same_bytes(const SimulatedScan& a, const SimulatedScan& b) {
  return a.points.size() == b.points.size() && a.labels == b.labels &&
         std::memcmp(a.points.data(), b.points.data(), a.points.size() * sizeof(Point)) == 0;
}

LidarModel test_model(std::vector<float> elevations, int columns, float dropout) {
  LidarModel m;
  m.name = "test";
  m.elevations_deg = std::move(elevations);
  m.columns = columns;
  m.dropout_probability = dropout;
  return m;
}

// ---------------------------------------------------------------------------------------
// Models.

TEST(LidarModel, Hdl64eLayout) {
  const LidarModel m = hdl64e();
  ASSERT_EQ(m.elevations_deg.size(), 64u);
  EXPECT_EQ(m.columns, 2118);
  EXPECT_EQ(m.rays_per_scan(), 64u * 2118u);
  EXPECT_NEAR(m.elevations_deg[0], 2.0f, 1e-5f);
  EXPECT_NEAR(m.elevations_deg[31], -8.33f, 1e-5f);
  EXPECT_NEAR(m.elevations_deg[32], -8.83f, 1e-5f);
  EXPECT_NEAR(m.elevations_deg[63], -24.9f, 1e-5f);
  // Even spacing within each block, strictly descending overall.
  for (int i = 1; i < 32; ++i) {
    EXPECT_NEAR(m.elevations_deg[i - 1] - m.elevations_deg[i], 10.33f / 31.0f, 1e-4f);
    EXPECT_NEAR(m.elevations_deg[31 + i] - m.elevations_deg[32 + i], 16.07f / 31.0f, 1e-4f);
  }
  for (int i = 1; i < 64; ++i) EXPECT_LT(m.elevations_deg[i], m.elevations_deg[i - 1]);
  EXPECT_FLOAT_EQ(m.max_range_m, 120.0f);
  EXPECT_FLOAT_EQ(m.range_noise_sigma_m, 0.02f);
  EXPECT_GE(m.dropout_probability, 0.01f);
  EXPECT_LE(m.dropout_probability, 0.03f);
  EXPECT_EQ(m.name, "hdl64e");
}

TEST(LidarModel, Vlp16AndOs1Layouts) {
  const LidarModel v = vlp16();
  ASSERT_EQ(v.elevations_deg.size(), 16u);
  EXPECT_EQ(v.columns, 1800);
  EXPECT_FLOAT_EQ(v.max_range_m, 100.0f);
  EXPECT_FLOAT_EQ(v.range_noise_sigma_m, 0.03f);
  EXPECT_NEAR(*std::max_element(v.elevations_deg.begin(), v.elevations_deg.end()), 15.0f, 1e-5f);
  EXPECT_NEAR(*std::min_element(v.elevations_deg.begin(), v.elevations_deg.end()), -15.0f, 1e-5f);
  for (size_t i = 1; i < 16; ++i) {
    EXPECT_NEAR(std::fabs(v.elevations_deg[i] - v.elevations_deg[i - 1]), 2.0f, 1e-5f);
  }
  const LidarModel o = os1_64();
  ASSERT_EQ(o.elevations_deg.size(), 64u);
  EXPECT_EQ(o.columns, 1024);
  EXPECT_FLOAT_EQ(o.max_range_m, 120.0f);
  EXPECT_FLOAT_EQ(o.range_noise_sigma_m, 0.03f);
  EXPECT_NEAR(o.elevations_deg.front(), 16.6f, 1e-5f);
  EXPECT_NEAR(o.elevations_deg.back(), -16.6f, 1e-5f);
  for (size_t i = 1; i < 64; ++i) {
    EXPECT_NEAR(o.elevations_deg[i - 1] - o.elevations_deg[i], 33.2f / 63.0f, 1e-4f);
  }
  const LidarModel h = hdl32e();
  ASSERT_EQ(h.elevations_deg.size(), 32u);
  EXPECT_EQ(h.columns, 2250);
  EXPECT_NEAR(h.elevations_deg.front(), 10.67f, 1e-5f);
  EXPECT_NEAR(h.elevations_deg.back(), -30.67f, 1e-5f);
  EXPECT_NEAR(h.elevations_deg[0] - h.elevations_deg[1], 41.34f / 31.0f, 1e-4f);
  const LidarModel w = os0_64();
  ASSERT_EQ(w.elevations_deg.size(), 64u);
  EXPECT_NEAR(w.elevations_deg.front(), 45.0f, 1e-5f);
  EXPECT_NEAR(w.elevations_deg.back(), -45.0f, 1e-5f);
  EXPECT_FLOAT_EQ(w.mount_height_m, 1.5f);
  EXPECT_FLOAT_EQ(w.max_range_m, 50.0f);
}

TEST(LidarModel, LookupByName) {
  EXPECT_EQ(lidar_model_by_name("hdl64e").elevations_deg.size(), 64u);
  EXPECT_EQ(lidar_model_by_name("vlp16").columns, 1800);
  EXPECT_EQ(lidar_model_by_name("os1-64").columns, 1024);
  EXPECT_EQ(lidar_model_by_name("os1_64").columns, 1024);
  EXPECT_EQ(lidar_model_by_name("hdl32e").elevations_deg.size(), 32u);
  EXPECT_EQ(lidar_model_by_name("os0-64").elevations_deg.size(), 64u);
  try {
    lidar_model_by_name("hdl32");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("hdl32"), std::string::npos) << what;
    EXPECT_NE(what.find("hdl64e"), std::string::npos) << what;
    EXPECT_NE(what.find("vlp16"), std::string::npos) << what;
    EXPECT_NE(what.find("os1-64"), std::string::npos) << what;
  }
  EXPECT_THROW(lidar_model_by_name(""), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------
// Scans.

TEST(LidarScan, GroundPlaneFromMountHeight) {
  const RayCaster caster(ground_scene());
  const LidarModel m = hdl64e();
  const double h = m.mount_height_m;
  const SimulatedScan scan = simulate_scan(caster, m, pose(3, -2, h), 11);
  ASSERT_EQ(scan.points.size(), scan.labels.size());
  // Beams that can reach the ground within max range.
  size_t hitting_beams = 0;
  for (float el : m.elevations_deg) {
    if (el < 0 && h / std::sin(-el * kPi / 180.0) <= m.max_range_m) ++hitting_beams;
  }
  EXPECT_EQ(hitting_beams, 55u);  // 9 upper beams look up or too flat for 120 m
  const double expected = static_cast<double>(hitting_beams * m.columns);
  EXPECT_NEAR(scan.points.size() / expected, 1.0 - m.dropout_probability, 0.005);
  const double tol = 4.0 * m.range_noise_sigma_m;
  for (size_t i = 0; i < scan.points.size(); ++i) {
    const Point& p = scan.points[i];
    ASSERT_NEAR(p.z, -h, tol) << i;
    ASSERT_EQ(scan.labels[i], kGroundLabel);
    ASSERT_LT(elevation_deg(p), -0.8);  // only downward beams (steeper than ~0.83 deg)
    ASSERT_GE(p.intensity, 0.0f);
    ASSERT_LE(p.intensity, 1.0f);
    // The steepest beam (-24.9 deg) lands 3.73 m away, the flattest usable one < 120 m.
    const double r = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    ASSERT_GT(r, 4.0);
    ASSERT_LT(r, 120.1);
  }
}

TEST(LidarScan, PointsAreOrderedByColumnThenBeam) {
  const RayCaster caster(ground_scene());
  const LidarModel m = hdl64e();
  const SimulatedScan scan = simulate_scan(caster, m, pose(0, 0, m.mount_height_m), 5);
  ASSERT_GT(scan.points.size(), 1000u);
  const double col_step = 2 * kPi / m.columns;
  int column = -1;
  double prev_el = 1e9;
  for (const Point& p : scan.points) {
    const int c = static_cast<int>(std::lround(azimuth(p) / col_step)) % m.columns;
    ASSERT_GE(c, column);
    if (c != column) {
      column = c;
      prev_el = 1e9;
    }
    const double el = elevation_deg(p);
    ASSERT_LT(el, prev_el);  // beams top-down within a column
    prev_el = el;
  }
  EXPECT_EQ(column, m.columns - 1);
  // Column 0 is at azimuth 0 exactly: its points have y == 0.
  EXPECT_FLOAT_EQ(scan.points.front().y, 0.0f);
  EXPECT_GT(scan.points.front().x, 0.0f);
}

TEST(LidarScan, DeterministicForASeedAndDifferentAcrossSeeds) {
  const RayCaster caster(ground_scene());
  const LidarModel m = vlp16();
  const Pose3d T = pose(1, 2, 1.73, 0.4);
  const SimulatedScan a = simulate_scan(caster, m, T, 42);
  const SimulatedScan b = simulate_scan(caster, m, T, 42);
  const SimulatedScan c = simulate_scan(caster, m, T, 43);
  ASSERT_FALSE(a.points.empty());
  EXPECT_TRUE(same_bytes(a, b));
  EXPECT_FALSE(same_bytes(a, c));
  // Without dropout the same rays return, so the difference is the range noise.
  LidarModel nodrop = m;
  nodrop.dropout_probability = 0.0f;
  const SimulatedScan d = simulate_scan(caster, nodrop, T, 42);
  const SimulatedScan e = simulate_scan(caster, nodrop, T, 43);
  ASSERT_EQ(d.points.size(), e.points.size());
  size_t differ = 0;
  for (size_t i = 0; i < d.points.size(); ++i) {
    if (d.points[i].x != e.points[i].x || d.points[i].z != e.points[i].z) ++differ;
  }
  EXPECT_GT(differ, d.points.size() * 9 / 10);
}

TEST(LidarScan, NoiseHasTheConfiguredSigma) {
  const RayCaster caster(ground_scene(100.0f));
  LidarModel m = test_model({-30.0f}, 20000, 0.0f);
  m.range_noise_sigma_m = 0.05f;
  const double h = 2.0;
  const SimulatedScan scan = simulate_scan(caster, m, pose(0, 0, h), 3);
  ASSERT_EQ(scan.points.size(), 20000u);
  const double true_range = h / std::sin(30.0 * kPi / 180.0);
  double sum = 0, sum2 = 0;
  for (const Point& p : scan.points) {
    const double err = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z) - true_range;
    sum += err;
    sum2 += err * err;
  }
  const double mean = sum / scan.points.size();
  const double sd = std::sqrt(sum2 / scan.points.size() - mean * mean);
  EXPECT_NEAR(mean, 0.0, 0.002);
  EXPECT_NEAR(sd, 0.05, 0.002);
  // Zero sigma gives exact ranges.
  m.range_noise_sigma_m = 0.0f;
  const SimulatedScan exact = simulate_scan(caster, m, pose(0, 0, h), 3);
  for (const Point& p : exact.points) ASSERT_NEAR(p.z, -h, 1e-4);
}

TEST(LidarScan, DropoutFractionMatchesTheModel) {
  const RayCaster caster(ground_scene());
  // All beams look steeply down, so every ray would hit.
  std::vector<float> els;
  for (int i = 0; i < 32; ++i) els.push_back(-10.0f - i);
  for (float p : {0.0f, 0.02f, 0.1f, 0.5f}) {
    const LidarModel m = test_model(els, 2000, p);
    const SimulatedScan scan = simulate_scan(caster, m, pose(0, 0, 1.73), 9);
    const double kept = static_cast<double>(scan.points.size()) / m.rays_per_scan();
    const double sd = std::sqrt(p * (1 - p) / m.rays_per_scan());
    EXPECT_NEAR(kept, 1.0 - p, 5 * sd + 1e-9) << "dropout " << p;
  }
  const LidarModel all = test_model(els, 100, 1.0f);
  EXPECT_TRUE(simulate_scan(caster, all, pose(0, 0, 1.73), 9).points.empty());
}

// A tall box 10 m ahead of the sensor (front face at 9.5 m, 2 m wide), no ground. Every
// beam of every model hits its front face within +-atan(1 / 9.5) of its direction.
Scene box_ahead(const Eigen::Vector3f& centre, float yaw = 0.0f) {
  return {Primitive::box(centre, {0.5f, 1.0f, 10.0f}, yaw, kBoxLabel, 0.8f)};
}

TEST(LidarScan, BoxAheadAppearsAtAzimuthZero) {
  const RayCaster caster(box_ahead({10, 0, 0}));
  const LidarModel m = hdl64e();
  const SimulatedScan scan = simulate_scan(caster, m, pose(0, 0, 0), 1);
  ASSERT_FALSE(scan.points.empty());
  const double half_width = std::atan2(1.0, 9.5);
  bool column0 = false;
  for (size_t i = 0; i < scan.points.size(); ++i) {
    const Point& p = scan.points[i];
    EXPECT_EQ(scan.labels[i], kBoxLabel);
    double az = std::atan2(p.y, p.x);
    EXPECT_LE(std::fabs(az), half_width + 0.01);
    EXPECT_NEAR(p.x, 9.5, 5 * m.range_noise_sigma_m);  // 5 sigma: thousands of points
    if (p.y == 0.0f) column0 = true;
  }
  EXPECT_TRUE(column0);
  // Expected number of returns: columns within +-atan(1/9.5) times the beams that hit the
  // front face (|z| <= 3 at 9.5 m), minus dropout.
  int cols = 0;
  for (int c = 0; c < m.columns; ++c) {
    const double az = 2 * kPi * c / m.columns;
    if (std::fabs(std::tan(az)) * 9.5 < 1.0 && std::cos(az) > 0) ++cols;
  }
  const double expected = cols * 64 * (1.0 - m.dropout_probability);
  EXPECT_NEAR(scan.points.size() / expected, 1.0, 0.05);
}

TEST(LidarScan, SingleBeamIntensityAndExactRange) {
  // One horizontal beam, box face at normal incidence in column 0.
  const RayCaster caster(box_ahead({10, 0, 0}));
  LidarModel m = test_model({0.0f}, 3600, 0.0f);
  m.range_noise_sigma_m = 0.0f;
  const SimulatedScan scan = simulate_scan(caster, m, pose(0, 0, 0), 1);
  ASSERT_FALSE(scan.points.empty());
  const Point& p0 = scan.points.front();
  EXPECT_FLOAT_EQ(p0.y, 0.0f);
  EXPECT_NEAR(p0.x, 9.5f, 1e-4f);
  EXPECT_NEAR(p0.z, 0.0f, 1e-6f);
  // reflectivity 0.8 * (0.3 + 0.7 * 1) * noise in [0.9, 1.1]
  EXPECT_GE(p0.intensity, 0.8f * 0.9f - 1e-5f);
  EXPECT_LE(p0.intensity, 0.8f * 1.1f + 1e-5f);
  // Oblique incidence: the same box yawed by 60 deg is hit at 9 m with cos(incidence) 0.5.
  const RayCaster yawed(box_ahead({10, 0, 0}, static_cast<float>(kPi / 3)));
  const SimulatedScan ys = simulate_scan(yawed, m, pose(0, 0, 0), 1);
  ASSERT_FALSE(ys.points.empty());
  const Point& q = ys.points.front();
  EXPECT_FLOAT_EQ(q.y, 0.0f);
  EXPECT_NEAR(q.x, 9.0f, 1e-4f);
  EXPECT_GE(q.intensity, 0.8f * 0.65f * 0.9f - 1e-5f);
  EXPECT_LE(q.intensity, 0.8f * 0.65f * 1.1f + 1e-5f);
}

TEST(LidarScan, RotatedAndTranslatedSensorSeesTheBoxAtTheMatchingAzimuth) {
  // Box 10 m along world +x from the sensor; the sensor is yawed +90 deg, so its x axis
  // points along world +y and the box lies at sensor azimuth -90 deg (270 deg), at
  // sensor-frame (0, -9.5, *).
  const Eigen::Vector3f sensor(20, -30, 1.5f);
  const RayCaster caster(box_ahead(sensor + Eigen::Vector3f(10, 0, 0)));
  const LidarModel m = hdl64e();
  const SimulatedScan scan = simulate_scan(caster, m, pose(20, -30, 1.5, kPi / 2), 2);
  ASSERT_FALSE(scan.points.empty());
  double mean_az = 0;
  for (const Point& p : scan.points) {
    mean_az += azimuth(p);
    EXPECT_NEAR(p.y, -9.5, 5 * m.range_noise_sigma_m);
    EXPECT_LE(std::fabs(p.x), 1.05);
  }
  mean_az /= scan.points.size();
  EXPECT_NEAR(mean_az, 1.5 * kPi, 0.01);
  // Pitched as well (10 deg about the sensor y axis): sensor y is unchanged, and the points
  // mapped back to the world lie on the box's front face x = 29.5.
  Pose3d pitched = pose(20, -30, 1.5, kPi / 2);
  pitched.linear() = pitched.linear() * Eigen::AngleAxisd(10 * kPi / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  for (const Pose3d& T : {pose(20, -30, 1.5, kPi / 2), pitched}) {
    const SimulatedScan ps = simulate_scan(caster, m, T, 2);
    ASSERT_GT(ps.points.size(), 1000u);
    for (const Point& p : ps.points) {
      EXPECT_NEAR(p.y, -9.5, 5 * m.range_noise_sigma_m);
      const Eigen::Vector3d w = T * p.xyz().cast<double>();
      EXPECT_NEAR(w.x(), 29.5, 5 * m.range_noise_sigma_m);
      EXPECT_LE(std::fabs(w.y() + 30.0), 1.01);  // + the noise's lateral component
    }
  }
}

TEST(LidarScan, EmptyModelsAndScenesGiveEmptyScans) {
  const RayCaster ground(ground_scene());
  EXPECT_TRUE(simulate_scan(ground, test_model({}, 100, 0.0f), pose(0, 0, 1), 1).points.empty());
  EXPECT_TRUE(simulate_scan(ground, test_model({-10}, 0, 0.0f), pose(0, 0, 1), 1).points.empty());
  const RayCaster empty(Scene{});
  const SimulatedScan s = simulate_scan(empty, hdl64e(), pose(0, 0, 1), 1);
  EXPECT_TRUE(s.points.empty());
  EXPECT_TRUE(s.labels.empty());
}

TEST(LidarScan, AllModelsRunOnTheGround) {
  const RayCaster caster(ground_scene());
  for (const char* name : {"hdl64e", "hdl32e", "vlp16", "os1-64", "os0-64"}) {
    const LidarModel m = lidar_model_by_name(name);
    const SimulatedScan s = simulate_scan(caster, m, pose(0, 0, m.mount_height_m), 4);
    EXPECT_GT(s.points.size(), m.rays_per_scan() / 4) << name;
    EXPECT_LT(s.points.size(), m.rays_per_scan()) << name;
    EXPECT_EQ(s.points.size(), s.labels.size());
  }
}

}  // namespace
}  // namespace segmatch::sim
