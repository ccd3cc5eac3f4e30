// The auto profile's measurements on generated scans of known geometry: a 360-degree spinning
// scan (raw and voxel-downsampled) and a 70-degree forward cone.
#include "segmatch/core/profile/input_profile.h"
#include "segmatch/core/preprocess/preprocess.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace segmatch;

namespace {

constexpr double kPi = 3.14159265358979323846;

// Rays from the origin onto a cylinder wall of radius wall_m (and the ground 1.7 m below),
// over azimuths [-half_fov, half_fov] and elevations -15..15 deg.
PointCloud scan_of(double half_fov_deg, int beams, int columns, double wall_m) {
  PointCloud out;
  for (int b = 0; b < beams; ++b) {
    const double el = (-15.0 + 30.0 * b / (beams - 1)) * kPi / 180.0;
    for (int c = 0; c < columns; ++c) {
      const double az = (-half_fov_deg + 2.0 * half_fov_deg * c / columns) * kPi / 180.0;
      double r = wall_m / std::cos(el);
      if (el < 0) r = std::min(r, 1.7 / std::sin(-el));
      const double rxy = r * std::cos(el);
      out.push_back({static_cast<float>(rxy * std::cos(az)), static_cast<float>(rxy * std::sin(az)),
                     static_cast<float>(r * std::sin(el)), 0.f});
    }
  }
  return out;
}

Poses straight_line(size_t n, double step_m) {
  Poses p;
  for (size_t i = 0; i < n; ++i) {
    Pose3d T = Pose3d::Identity();
    T.translation().x() = step_m * static_cast<double>(i);
    p.push_back(T);
  }
  return p;
}

}  // namespace

TEST(InputProfile, RawSpinningScanIsDenseSpinning) {
  const std::vector<PointCloud> scans(3, scan_of(180.0, 64, 1024, 20.0));
  const InputMeasurements m = measure_input(scans, straight_line(10, 0.5));
  EXPECT_GT(m.azimuth_coverage, 0.95);
  EXPECT_NEAR(m.elevation_max_deg, 15.0, 1.0);
  EXPECT_LT(m.spacing_p10_m, 0.06);
  EXPECT_NEAR(m.scan_distance_m, 0.5, 1e-9);
  EXPECT_EQ(m.points_per_scan, 64.0 * 1024.0);
  EXPECT_EQ(m.sensor_class(), "dense-spinning");
}

TEST(InputProfile, VoxelizedKeyframeIsSparseSpinningWithItsLeaf) {
  VoxelGridConfig grid;
  grid.leaf_m = 0.25f;
  grid.min_points_per_voxel = 1;
  const PointCloud keyframe = voxel_filter(scan_of(180.0, 64, 2048, 20.0), grid);
  const InputMeasurements m = measure_input({keyframe, keyframe}, straight_line(5, 6.0));
  EXPECT_TRUE(m.downsampled);
  EXPECT_GT(m.spacing_p50_m, 0.15);
  EXPECT_LT(m.spacing_p50_m, 0.35);
  EXPECT_EQ(m.sensor_class(), "sparse-spinning");
}

TEST(InputProfile, ForwardConeIsNarrowFov) {
  const InputMeasurements m = measure_input({scan_of(35.0, 64, 400, 12.0)}, {});
  EXPECT_NEAR(m.azimuth_coverage, 70.0 / 360.0, 0.02);
  EXPECT_EQ(m.scan_distance_m, 0.0);
  EXPECT_EQ(m.sensor_class(), "narrow-fov");
  EXPECT_LT(m.range_p95_m, 13.0);
}

TEST(InputProfile, ScansToMeasureAreSpreadOverTheInput) {
  InputProfileConfig c;
  c.max_scans = 4;
  EXPECT_EQ(scans_to_measure(10, c), (std::vector<size_t>{0, 3, 6, 9}));
  EXPECT_EQ(scans_to_measure(2, c), (std::vector<size_t>{0, 1}));
  EXPECT_TRUE(scans_to_measure(0, c).empty());
}

TEST(InputProfile, NothingToMeasureIsRefused) {
  EXPECT_THROW(measure_input({}, {}), std::invalid_argument);
  EXPECT_THROW(measure_input({PointCloud(3)}, {}), std::invalid_argument);
  InputProfileConfig bad;
  bad.max_scans = 0;
  EXPECT_THROW(measure_input({scan_of(35.0, 8, 40, 10.0)}, {}, bad), std::invalid_argument);
}

// The same wall seen from two poses 2 m apart: the right poses put both scans on one surface,
// poses off by 3 m do not (riverside02's second half, docs/how-defaults-were-chosen.md).
TEST(InputProfile, PoseAgreementTellsRightFromWrongPoses) {
  const PointCloud a = scan_of(180.0, 32, 720, 15.0);
  Pose3d T_world_b = Pose3d::Identity();
  T_world_b.translation() << 2.0, 0.0, 0.0;
  PointCloud b;  // what the sensor at T_world_b sees of a's wall (a's points in b's frame)
  for (const Point& p : a) {
    const Eigen::Vector3f q = (T_world_b.inverse().cast<float>() * p.xyz());
    b.push_back({q.x(), q.y(), q.z(), 0.f});
  }
  EXPECT_GT(pose_agreement(a, Pose3d::Identity(), b, T_world_b, 0.75), 0.99);
  Pose3d wrong = T_world_b;
  wrong.translation() << 2.0, 3.0, 0.5;
  const double off = pose_agreement(a, Pose3d::Identity(), b, wrong, 0.75);
  EXPECT_LT(off, InputMeasurements::kMinAgreement);

  InputMeasurements m;
  check_pose_agreement({{&a, &b, Pose3d::Identity(), T_world_b, 7}, {&a, &b, Pose3d::Identity(), wrong, 8}}, m);
  EXPECT_EQ(m.pairs_checked, 2u);
  EXPECT_EQ(m.pairs_disagreeing, 1u);
  EXPECT_EQ(m.disagreeing_pairs, (std::vector<size_t>{8}));
}

namespace {

// A spinning scan of `beams` rings evenly from lo_deg to hi_deg (a wall 20 m away, the ground
// 1.7 m below), each point's elevation jittered by up to jitter_deg.
PointCloud ring_scan(int beams, double lo_deg, double hi_deg, double jitter_deg = 0.0) {
  PointCloud out;
  uint32_t state = 12345;
  auto jitter = [&] {
    state = state * 1664525u + 1013904223u;
    return jitter_deg * (2.0 * (state >> 8) / double(1u << 24) - 1.0);
  };
  for (int b = 0; b < beams; ++b)
    for (int c = 0; c < 1024; ++c) {
      const double el = (lo_deg + (hi_deg - lo_deg) * b / (beams - 1) + jitter()) * kPi / 180.0;
      const double az = 2.0 * kPi * c / 1024;
      double r = 20.0 / std::cos(el);
      if (el < 0) r = std::min(r, 1.7 / std::sin(-el));
      const double rxy = r * std::cos(el);
      out.push_back({static_cast<float>(rxy * std::cos(az)), static_cast<float>(rxy * std::sin(az)),
                     static_cast<float>(r * std::sin(el)), 0.f});
    }
  return out;
}

}  // namespace

// The beam layout from the elevations alone: the ring count and step of the common sensors
// (VLP-16, HDL-32E, HDL-64E, OS0-64), with and without a jitter of a few hundredths of a degree.
TEST(InputProfile, BeamLayoutCountsTheRingsOfASpinningScan) {
  struct Case {
    int beams;
    double lo, hi;
    const char* layout;
  };
  for (const Case& c : {Case{16, -15.0, 15.0, "16-beam spinning"}, Case{32, -30.67, 10.67, "32-beam spinning"},
                        Case{64, -24.9, 2.0, "64/128-beam spinning"}, Case{64, -45.0, 45.0, "wide-fov spinning"}})
    for (double jitter : {0.0, 0.03}) {
      const InputMeasurements m = measure_input({ring_scan(c.beams, c.lo, c.hi, jitter)}, {});
      // The count spans every point's elevations (1st to 99th percentile): within a ring or two.
      EXPECT_NEAR(m.ring_count, c.beams, 2.0) << c.beams << " beams, jitter " << jitter;
      EXPECT_NEAR(m.ring_spacing_deg, (c.hi - c.lo) / (c.beams - 1), 0.05) << c.beams << " beams";
      EXPECT_EQ(m.beam_layout(), c.layout) << c.beams << " beams, jitter " << jitter;
      EXPECT_EQ(m.sensor_class(), "dense-spinning") << "the parameters' class is unchanged";
    }
}

TEST(InputProfile, KeyframesAndConesHaveNoRings) {
  VoxelGridConfig grid;
  grid.leaf_m = 0.25f;
  grid.min_points_per_voxel = 1;
  const PointCloud keyframe = voxel_filter(ring_scan(64, -15.0, 15.0), grid);
  const InputMeasurements k = measure_input({keyframe, keyframe}, straight_line(5, 6.0));
  EXPECT_EQ(k.ring_count, 0.0);
  EXPECT_EQ(k.beam_layout(), "slam keyframes");
  EXPECT_EQ(measure_input({scan_of(35.0, 64, 400, 12.0)}, {}).beam_layout(), "narrow-fov");
  // Elevations spread evenly (a non-repetitive pattern): no group holds the points.
  std::vector<double> spread;
  for (int i = 0; i < 20000; ++i) spread.push_back(-30.0 + 60.0 * i / 20000.0);
  EXPECT_LT(measure_rings(spread).share, InputMeasurements::kRingsResolvedShare);
  const Rings rings = measure_rings({});
  EXPECT_EQ(rings.count, 0u);
}
