// Tests of the segment descriptors (SegMatch section III-C): Weinmann eigenvalue features and
// the Ensemble of Shape Functions.
#include "segmatch/core/description/descriptors.h"
#include "segmatch/core/detail/random.h"
#include "support/validation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace {

Point make_point(const Eigen::Vector3f& v) { return Point{v.x(), v.y(), v.z(), 0.f}; }

// Zero-mean Gaussian cloud with the given standard deviations along x, y, z.
PointCloud gaussian_cloud(int n, const Eigen::Vector3f& sigma, uint64_t seed) {
  Rng rng(seed);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    cloud.push_back(make_point(Eigen::Vector3f(static_cast<float>(rng.normal(0, sigma.x())),
                                               static_cast<float>(rng.normal(0, sigma.y())),
                                               static_cast<float>(rng.normal(0, sigma.z())))));
  }
  return cloud;
}

PointCloud transformed(const PointCloud& cloud, const Eigen::Affine3f& T) {
  PointCloud out;
  for (const Point& p : cloud) out.push_back(make_point(T * p.xyz()));
  return out;
}

Eigen::Affine3f some_motion() {
  Eigen::Affine3f T = Eigen::Affine3f::Identity();
  T.translate(Eigen::Vector3f(12.f, -40.f, 3.5f));
  T.rotate(Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1.f, 2.f, 3.f).normalized()));
  return T;
}

// Vertical pole: cylinder surface, radius 0.15 m, height 3 m.
PointCloud pole_cloud(int n, uint64_t seed) {
  Rng rng(seed);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    const double a = rng.uniform(0, 6.283185307179586);
    cloud.push_back(
        make_point(Eigen::Vector3f(static_cast<float>(0.15 * std::cos(a)), static_cast<float>(0.15 * std::sin(a)),
                                   static_cast<float>(rng.uniform(0, 3)))));
  }
  return cloud;
}

// Surface of a 2 x 1.5 x 1 m box.
PointCloud box_cloud(int n, uint64_t seed) {
  Rng rng(seed);
  const Eigen::Vector3f half(1.f, 0.75f, 0.5f);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3f p(static_cast<float>(rng.uniform(-1, 1)), static_cast<float>(rng.uniform(-1, 1)),
                      static_cast<float>(rng.uniform(-1, 1)));
    const int axis = rng.uniform_int(0, 2);
    p[axis] = rng.bernoulli(0.5) ? 1.f : -1.f;
    cloud.push_back(make_point(p.cwiseProduct(half)));
  }
  return cloud;
}

// Surface of a sphere of radius 0.8 m.
PointCloud sphere_cloud(int n, uint64_t seed) {
  Rng rng(seed);
  PointCloud cloud;
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3f v(static_cast<float>(rng.normal()), static_cast<float>(rng.normal()),
                      static_cast<float>(rng.normal()));
    cloud.push_back(make_point(0.8f * v.normalized()));
  }
  return cloud;
}

float intersection(const EsfDescriptor& a, const EsfDescriptor& b) {
  float s = 0.f;
  for (size_t i = 0; i < a.size(); ++i) s += std::min(a[i], b[i]);
  return s;
}

float block_sum(const EsfDescriptor& d, int h) {
  return std::accumulate(d.begin() + h * 64, d.begin() + (h + 1) * 64, 0.f);
}

bool all_zero(const EigenFeatures& f) {
  return std::all_of(f.begin(), f.end(), [](float v) { return v == 0.f; });
}

bool all_zero(const EsfDescriptor& f) {
  return std::all_of(f.begin(), f.end(), [](float v) { return v == 0.f; });
}

enum { kLinearity, kPlanarity, kScattering, kOmnivariance, kAnisotropy, kEntropy, kCurvature };

TEST(EigenFeatures, LineIsLinear) {
  // Along z: an ascending sort (the original SegMatch bug) would make this look scattered.
  const EigenFeatures f = eigen_features(gaussian_cloud(2000, {0.01f, 0.01f, 5.f}, 1));
  EXPECT_GT(f[kLinearity], 0.99f);
  EXPECT_LT(f[kPlanarity], 0.01f);
  EXPECT_LT(f[kScattering], 0.01f);
  EXPECT_GT(f[kAnisotropy], 0.99f);
}

TEST(EigenFeatures, PlaneIsPlanar) {
  Rng rng(2);
  PointCloud cloud;
  for (int i = 0; i < 4000; ++i) {
    cloud.push_back(
        make_point(Eigen::Vector3f(static_cast<float>(rng.uniform(-5, 5)), static_cast<float>(rng.uniform(-5, 5)),
                                   static_cast<float>(rng.normal(0, 0.01)))));
  }
  const EigenFeatures f = eigen_features(transformed(cloud, some_motion()));
  EXPECT_GT(f[kPlanarity], 0.95f);
  EXPECT_LT(f[kLinearity], 0.05f);
  EXPECT_LT(f[kScattering], 0.01f);
}

TEST(EigenFeatures, IsotropicCloudIsScattered) {
  const EigenFeatures f = eigen_features(gaussian_cloud(20000, {1.f, 1.f, 1.f}, 3));
  EXPECT_GT(f[kScattering], 0.95f);
  EXPECT_NEAR(f[kOmnivariance], 1.f / 3.f, 0.005f);
  EXPECT_NEAR(f[kEntropy], std::log(3.f), 0.005f);
  EXPECT_NEAR(f[kCurvature], 1.f / 3.f, 0.01f);
  EXPECT_LT(f[kLinearity], 0.05f);
}

TEST(EigenFeatures, AnisotropicGaussianMatchesClosedForm) {
  // Sigmas 3, 2, 1 -> variances 9, 4, 1 -> normalised eigenvalues 9/14, 4/14, 1/14,
  // whatever the orientation of the cloud.
  const PointCloud cloud = transformed(gaussian_cloud(50000, {1.f, 3.f, 2.f}, 4), some_motion());
  const double l1 = 9.0 / 14, l2 = 4.0 / 14, l3 = 1.0 / 14;
  const double expected[kEigenFeatureCount] = {(l1 - l2) / l1,
                                               (l2 - l3) / l1,
                                               l3 / l1,
                                               std::cbrt(l1 * l2 * l3),
                                               (l1 - l3) / l1,
                                               -(l1 * std::log(l1) + l2 * std::log(l2) + l3 * std::log(l3)),
                                               l3};
  const EigenFeatures f = eigen_features(cloud);
  for (int i = 0; i < kEigenFeatureCount; ++i) {
    EXPECT_NEAR(f[static_cast<size_t>(i)], expected[i], 0.01) << "feature " << i;
  }
}

TEST(EigenFeatures, DegenerateInputsGiveZeros) {
  EXPECT_TRUE(all_zero(eigen_features({})));
  EXPECT_TRUE(all_zero(eigen_features({Point{1, 2, 3, 0}})));
  EXPECT_TRUE(all_zero(eigen_features({Point{1, 2, 3, 0}, Point{4, 5, 6, 0}})));
  EXPECT_TRUE(all_zero(eigen_features(PointCloud(100, Point{1e4f, -3e3f, 7.f, 0.f}))));
}

TEST(EigenFeatures, ExactLineHasNoNaN) {
  PointCloud cloud;
  for (int i = 0; i < 50; ++i) cloud.push_back(Point{static_cast<float>(i), 0.f, 0.f, 0.f});
  const EigenFeatures f = eigen_features(cloud);
  for (float v : f) EXPECT_TRUE(std::isfinite(v));
  EXPECT_NEAR(f[kLinearity], 1.f, 1e-6f);
  EXPECT_NEAR(f[kEntropy], 0.f, 1e-6f);
  EXPECT_NEAR(f[kOmnivariance], 0.f, 1e-6f);
}

TEST(EsfDescriptor, HasPclLayoutAndNormalisation) {
  const EsfDescriptor d = esf_descriptor(box_cloud(1500, 5), 2000, 7);
  ASSERT_EQ(d.size(), 640u);
  for (float v : d) EXPECT_GE(v, 0.f);
  EXPECT_NEAR(std::accumulate(d.begin(), d.end(), 0.0), 1.0, 1e-4);
  // Undo PCL's weights: every triple adds 1 to one D3 bin and 3 to D2 bins.
  const float d3 = block_sum(d, 3) / 0.5f + block_sum(d, 4) / 0.5f + block_sum(d, 5) / 1.f;
  const float d2 = block_sum(d, 6) / 0.5f + block_sum(d, 7) / 2.f + block_sum(d, 8) / 2.f;
  EXPECT_NEAR(d2 / d3, 3.f, 1e-3f);
  // Every mixed D2 edge also goes to the in-ratio histogram (weight 1 vs 2).
  EXPECT_NEAR(block_sum(d, 9), block_sum(d, 8) / 2.f, 1e-5f);
  EXPECT_GT(block_sum(d, 8), 0.f);
  // A3 total: sum over triples of the 3 edge voxel counts / 32, so > 0 for a real shape.
  EXPECT_GT(block_sum(d, 0) + block_sum(d, 1) + block_sum(d, 2), 0.f);
}

TEST(EsfDescriptor, DeterministicForASeed) {
  const PointCloud cloud = sphere_cloud(1000, 6);
  const EsfDescriptor a = esf_descriptor(cloud, 1500, 42);
  const EsfDescriptor b = esf_descriptor(cloud, 1500, 42);
  const EsfDescriptor c = esf_descriptor(cloud, 1500, 43);
  EXPECT_EQ(std::memcmp(a.data(), b.data(), sizeof(float) * a.size()), 0);
  EXPECT_NE(std::memcmp(a.data(), c.data(), sizeof(float) * a.size()), 0);
}

TEST(EsfDescriptor, NearlyInvariantToRigidMotion) {
  // Same seed -> same triples; only the voxelisation changes with the pose. Measured
  // intersections: box 0.96, pole 0.92; a different seed on the same pose gives ~0.90-0.91,
  // so the pose changes the descriptor less than resampling does.
  for (const PointCloud& cloud : {box_cloud(1500, 8), pole_cloud(800, 9)}) {
    const EsfDescriptor a = esf_descriptor(cloud, 2000, 1);
    const EsfDescriptor b = esf_descriptor(transformed(cloud, some_motion()), 2000, 1);
    EXPECT_GT(intersection(a, b), 0.85f);
  }
}

TEST(EsfDescriptor, DistinguishesShapes) {
  const EsfDescriptor pole1 = esf_descriptor(pole_cloud(1000, 10), 2000, 1);
  const EsfDescriptor pole2 = esf_descriptor(pole_cloud(1000, 11), 2000, 2);
  const EsfDescriptor box1 = esf_descriptor(box_cloud(1000, 12), 2000, 1);
  const EsfDescriptor box2 = esf_descriptor(box_cloud(1000, 13), 2000, 2);
  const EsfDescriptor sph1 = esf_descriptor(sphere_cloud(1000, 14), 2000, 1);
  const EsfDescriptor sph2 = esf_descriptor(sphere_cloud(1000, 15), 2000, 2);
  const float same = std::min({intersection(pole1, pole2), intersection(box1, box2), intersection(sph1, sph2)});
  const float different = std::max({intersection(pole1, box1), intersection(pole1, sph1), intersection(box1, sph1)});
  // Measured: same >= 0.89, different <= 0.58 (box vs sphere is the closest pair).
  EXPECT_GT(same, 0.8f);
  EXPECT_LT(different, same - 0.15f);
}

TEST(EsfDescriptor, DegenerateInputsGiveZeros) {
  EXPECT_TRUE(all_zero(esf_descriptor({}, 100, 1)));
  EXPECT_TRUE(all_zero(esf_descriptor({Point{1, 2, 3, 0}, Point{2, 2, 3, 0}}, 100, 1)));
  EXPECT_TRUE(all_zero(esf_descriptor(PointCloud(50, Point{1, 2, 3, 0}), 100, 1)));
  PointCloud line;  // exactly collinear: no triangle has an area (PCL would never return)
  for (int i = 0; i < 50; ++i) line.push_back(Point{static_cast<float>(i), 0.f, 0.f, 0.f});
  EXPECT_TRUE(all_zero(esf_descriptor(line, 100, 1)));
  EXPECT_THROW(esf_descriptor(line, 0, 1), std::invalid_argument);
}

Segments some_segments() {
  Segments segments(4);
  segments[0].points = pole_cloud(300, 20);
  segments[1].points = box_cloud(500, 21);
  segments[2].points = sphere_cloud(400, 22);
  segments[3].points = transformed(box_cloud(200, 23), some_motion());
  for (size_t i = 0; i < segments.size(); ++i) segments[i].id = 100 + i;
  return segments;
}

TEST(DescribeSegments, FillsDescriptorsAndFlags) {
  Segments segments = some_segments();
  segments.emplace_back();  // empty segment: described as zeros, centroid stays zero
  DescriptorConfig config;
  config.esf_samples = 500;
  describe_segments(segments, config);
  for (const Segment& s : segments) {
    EXPECT_TRUE(s.has_eigen);
    EXPECT_TRUE(s.has_esf);
    EXPECT_EQ(s.eigen, eigen_features(s.points));
    EXPECT_EQ(s.esf, esf_descriptor(s.points, 500, config.esf_seed));
  }
  EXPECT_FALSE(all_zero(segments[1].esf));
  EXPECT_TRUE(segments.back().centroid.isZero());
  // The centroid of segment 3 was recomputed (box moved by some_motion()).
  EXPECT_LT((segments[3].centroid - some_motion().translation()).norm(), 0.2f);
}

TEST(DescribeSegments, RespectsDisabledDescriptors) {
  Segments segments = some_segments();
  DescriptorConfig config;
  config.compute_esf = false;
  describe_segments(segments, config);
  EXPECT_TRUE(segments[0].has_eigen);
  EXPECT_FALSE(segments[0].has_esf);
  EXPECT_TRUE(all_zero(segments[0].esf));
}

TEST(DescribeSegments, IndependentOfOrder) {
  Segments a = some_segments();
  Segments b = some_segments();
  std::reverse(b.begin(), b.end());
  std::swap(b[0], b[2]);
  DescriptorConfig config;
  config.esf_samples = 400;
  describe_segments(a, config);
  describe_segments(b, config);
  for (const Segment& sa : a) {
    const auto it = std::find_if(b.begin(), b.end(), [&](const Segment& s) { return s.id == sa.id; });
    ASSERT_NE(it, b.end());
    EXPECT_EQ(sa.eigen, it->eigen);
    EXPECT_EQ(sa.esf, it->esf);
  }
}

TEST(DescribeSegments, ConfigValidationNamesTheField) {
  DescriptorConfig config;
  EXPECT_NO_THROW(config.validate());
  config.esf_samples = 0;
  EXPECT_NE(test::validation_message(config).find("esf_samples"), std::string::npos);
  Segments segments = some_segments();
  EXPECT_THROW(describe_segments(segments, config), std::invalid_argument);
}

}  // namespace
}  // namespace segmatch
