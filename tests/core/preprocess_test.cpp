#include "segmatch/core/preprocess/preprocess.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "segmatch/core/detail/random.h"
#include "support/validation.h"

namespace segmatch {
namespace {

using test::validation_message;

// ---------------------------------------------------------------- voxel grid

TEST(VoxelFilter, MergesPointsOfAVoxelIntoTheirCentroid) {
  const PointCloud cloud = {{0.01f, 0.02f, 0.03f, 1.f},
                            {0.55f, 0.55f, 0.55f, 9.f},  // alone in its voxel: dropped
                            {0.03f, 0.04f, 0.05f, 3.f},
                            {-0.05f, 0.02f, 0.02f, 4.f},  // voxel -1: alone
                            {0.05f, 0.06f, 0.07f, 5.f}};
  const PointCloud out = voxel_filter(cloud, VoxelGridConfig{});
  ASSERT_EQ(out.size(), 1u);
  EXPECT_NEAR(out[0].x, 0.03f, 1e-6);
  EXPECT_NEAR(out[0].y, 0.04f, 1e-6);
  EXPECT_NEAR(out[0].z, 0.05f, 1e-6);
  EXPECT_NEAR(out[0].intensity, 3.f, 1e-6);

  VoxelGridConfig keep_singles;
  keep_singles.min_points_per_voxel = 1;
  EXPECT_EQ(voxel_filter(cloud, keep_singles).size(), 3u);
}

TEST(VoxelFilter, KnownCountsOnAGrid) {
  PointCloud cloud;
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) {
      const int copies = (i + j) % 3;  // 0, 1 or 2 points in voxel (i, j)
      for (int k = 0; k < copies; ++k) {
        cloud.push_back({0.1f * i + 0.02f + 0.03f * k, 0.1f * j + 0.05f, 0.05f, 0.f});
      }
    }
  }
  int expected = 0;
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j) expected += (i + j) % 3 == 2;
  }
  EXPECT_EQ(voxel_filter(cloud, VoxelGridConfig{}).size(), size_t(expected));
}

TEST(VoxelFilter, MajorityLabelPerVoxel) {
  const PointCloud cloud = {{0.01f, 0.01f, 0.01f, 0.f}, {0.02f, 0.01f, 0.01f, 0.f}, {0.03f, 0.01f, 0.01f, 0.f},
                            {1.01f, 0.01f, 0.01f, 0.f}, {1.02f, 0.01f, 0.01f, 0.f}, {1.03f, 0.01f, 0.01f, 0.f},
                            {2.01f, 0.01f, 0.01f, 0.f}, {2.02f, 0.01f, 0.01f, 0.f}};
  const std::vector<uint32_t> labels = {7, 5, 5, 0, 0, 3, 9, 4};
  std::vector<uint32_t> labels_out;
  const PointCloud out = voxel_filter(cloud, VoxelGridConfig{}, &labels, &labels_out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(labels_out, (std::vector<uint32_t>{5, 3, 4}));  // majority, non-zero, tie->small
  const std::vector<uint32_t> wrong_size = {1, 2};
  EXPECT_THROW(voxel_filter(cloud, VoxelGridConfig{}, &wrong_size, &labels_out), std::invalid_argument);
}

TEST(VoxelFilter, OutputIsDeterministicAndSortedByVoxel) {
  Rng rng(7);
  PointCloud cloud(20000);
  for (auto& p : cloud) {
    p = {float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)), float(rng.uniform(0, 0.5)), 1.f};
  }
  cloud.push_back({NAN, 0.f, 0.f, 0.f});
  const PointCloud a = voxel_filter(cloud, VoxelGridConfig{});
  PointCloud shuffled = cloud;
  for (size_t i = shuffled.size() - 1; i > 0; --i) std::swap(shuffled[i], shuffled[rng.index(i + 1)]);
  const PointCloud b = voxel_filter(shuffled, VoxelGridConfig{});
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 100u);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_NEAR(a[i].x, b[i].x, 1e-5);
    EXPECT_NEAR(a[i].y, b[i].y, 1e-5);
    EXPECT_NEAR(a[i].z, b[i].z, 1e-5);
  }
  for (size_t i = 1; i < a.size(); ++i) {
    EXPECT_LE(std::floor(a[i - 1].x / 0.1f), std::floor(a[i].x / 0.1f));
  }
}

TEST(VoxelFilter, ValidationNamesTheField) {
  VoxelGridConfig c;
  EXPECT_EQ(validation_message(c), "");
  c.leaf_m = 0.f;
  EXPECT_NE(validation_message(c).find("leaf_m"), std::string::npos);
  c = {};
  c.min_points_per_voxel = 0;
  EXPECT_NE(validation_message(c).find("min_points_per_voxel"), std::string::npos);
}

// ---------------------------------------------------------------- ground removal

constexpr uint32_t kGround = 1;
constexpr uint32_t kObject = 2;

struct Scene {
  PointCloud cloud;
  std::vector<uint32_t> labels;
  void add(float x, float y, float z, uint32_t label) {
    cloud.push_back({x, y, z, 0.f});
    labels.push_back(label);
  }
};

// Surface of an axis-aligned box [x0, x0 + w] x [y0, y0 + w] x [z0 + 0.05, z0 + h] sampled at
// 0.1 m (sides and top), like voxel centroids.
void add_box(Scene* s, float x0, float y0, float z0, float w, float h) {
  const int n = int(std::lround(w / 0.1f)), m = int(std::lround(h / 0.1f));
  for (int k = 0; k < m; ++k) {
    const float z = z0 + 0.05f + 0.1f * k;
    for (int i = 0; i <= n; ++i) {
      s->add(x0 + 0.1f * i, y0, z, kObject);
      s->add(x0 + 0.1f * i, y0 + w, z, kObject);
      if (i > 0 && i < n) {
        s->add(x0, y0 + 0.1f * i, z, kObject);
        s->add(x0 + w, y0 + 0.1f * i, z, kObject);
      }
    }
  }
  for (int i = 1; i < n; ++i) {
    for (int j = 1; j < n; ++j) s->add(x0 + 0.1f * i, y0 + 0.1f * j, z0 + h, kObject);
  }
}

void add_pole(Scene* s, float cx, float cy, float z0, float radius, float h) {
  for (float z = z0 + 0.05f; z < z0 + h; z += 0.1f) {
    for (int a = 0; a < 12; ++a) {
      const float t = a * 6.2831853f / 12;
      s->add(cx + radius * std::cos(t), cy + radius * std::sin(t), z, kObject);
    }
  }
}

// 60 m x 20 m plane at a 4 % grade (2.4 m of climb), 0.1 m sampling with 1 cm noise, with
// boxes (2.5 m tall) and poles (5 m) standing on it; the plane under the boxes is hidden.
Scene sloped_scene() {
  Scene s;
  Rng rng(3);
  const auto ground_z = [](float x) { return 0.04f * x; };
  struct Box {
    float x, y;
  };
  const Box boxes[] = {{5.f, 2.f}, {22.f, -6.f}, {40.f, 4.f}, {55.f, -2.f}};
  for (int i = 0; i < 600; ++i) {
    for (int j = 0; j < 200; ++j) {
      const float x = 0.05f + 0.1f * i, y = -9.95f + 0.1f * j;
      bool hidden = false;
      for (const Box& b : boxes) hidden |= x > b.x && x < b.x + 1.5f && y > b.y && y < b.y + 1.5f;
      if (!hidden) s.add(x, y, ground_z(x) + float(rng.normal(0.0, 0.01)), kGround);
    }
  }
  for (const Box& b : boxes) add_box(&s, b.x, b.y, ground_z(b.x + 0.75f), 1.5f, 2.5f);
  for (float x : {10.f, 30.f, 48.f}) add_pole(&s, x, 7.f, ground_z(x), 0.15f, 5.f);
  return s;
}

struct Kept {
  double ground = 0, object = 0;
};
Kept kept_fractions(const Scene& s, const GroundConfig& config, const Eigen::Vector3f& sensor) {
  std::vector<uint32_t> labels_out;
  const PointCloud out = remove_ground(s.cloud, config, sensor, &s.labels, &labels_out);
  EXPECT_EQ(out.size(), labels_out.size());
  const double total_g = std::count(s.labels.begin(), s.labels.end(), kGround);
  const double total_o = std::count(s.labels.begin(), s.labels.end(), kObject);
  const double kept_g = std::count(labels_out.begin(), labels_out.end(), kGround);
  const double kept_o = std::count(labels_out.begin(), labels_out.end(), kObject);
  return {kept_g / total_g, kept_o / total_o};
}

TEST(Ground, ColumnVarianceRemovesASlopedPlaneAndKeepsObjects) {
  const Scene s = sloped_scene();
  const Kept kept = kept_fractions(s, GroundConfig{}, Eigen::Vector3f(30.f, 0.f, 3.0f));
  EXPECT_LT(kept.ground, 0.02);
  EXPECT_GT(kept.object, 0.95);
}

TEST(Ground, GlobalHeightThresholdFailsOnTheSlope) {
  // The reason for the column method: one threshold cannot fit 2.4 m of climb.
  const Scene s = sloped_scene();
  GroundConfig config;
  config.method = GroundRemoval::kHeightThreshold;
  const Kept kept = kept_fractions(s, config, Eigen::Vector3f(5.f, 0.f, 0.2f + 1.73f));
  EXPECT_GT(kept.ground, 0.5);
}

TEST(Ground, ColumnVarianceRemovesKerbsAndKeepsACarBody) {
  Scene s;
  for (int i = 0; i < 400; ++i) {
    const float x = 0.05f + 0.1f * i;
    for (int j = 0; j < 200; ++j) {
      const float y = -9.95f + 0.1f * j;
      if (x > 10.f && x < 14.5f && y > -4.f && y < -2.f) continue;  // under the car
      s.add(x, y, y < 0.f ? 0.f : 0.15f, kGround);                  // road | sidewalk
    }
    s.add(x, 0.f, 0.05f, kGround);  // kerb face
    s.add(x, 0.f, 0.1f, kGround);
  }
  add_box(&s, 10.f, -4.f, 0.25f, 2.0f, 1.3f);  // car body 0.3 .. 1.55 m above the road
  const Kept kept = kept_fractions(s, GroundConfig{}, Eigen::Vector3f(20.f, -5.f, 1.73f));
  EXPECT_LT(kept.ground, 0.02);
  EXPECT_GT(kept.object, 0.95);
}

TEST(Ground, HeightThresholdOnFlatGround) {
  Scene s;
  for (int i = 0; i < 200; ++i) {
    for (int j = 0; j < 200; ++j) s.add(0.1f * i, 0.1f * j, 0.02f * ((i + j) % 3), kGround);
  }
  add_box(&s, 5.f, 5.f, 0.3f, 1.f, 2.f);
  GroundConfig config;
  config.method = GroundRemoval::kHeightThreshold;
  const Kept kept = kept_fractions(s, config, Eigen::Vector3f(0.f, 0.f, 1.73f));
  EXPECT_EQ(kept.ground, 0.0);
  EXPECT_EQ(kept.object, 1.0);
  config.method = GroundRemoval::kNone;
  const Kept none = kept_fractions(s, config, Eigen::Vector3f(0.f, 0.f, 1.73f));
  EXPECT_EQ(none.ground, 1.0);
}

TEST(Ground, ValidationNamesTheField) {
  GroundConfig c;
  EXPECT_EQ(validation_message(c), "");
  c.column_size_m = -1.f;
  EXPECT_NE(validation_message(c).find("column_size_m"), std::string::npos);
  c = {};
  c.max_step_m = 0.f;
  EXPECT_NE(validation_message(c).find("max_step_m"), std::string::npos);
  c = {};
  c.ground_margin_m = -0.1f;
  EXPECT_NE(validation_message(c).find("ground_margin_m"), std::string::npos);
  c = {};
  c.max_search_rings = 0;
  EXPECT_NE(validation_message(c).find("max_search_rings"), std::string::npos);
  c = {};
  c.sensor_height_m = NAN;
  EXPECT_NE(validation_message(c).find("sensor_height_m"), std::string::npos);
}

}  // namespace
}  // namespace segmatch
