// Range-image segmentation (Bogoslavskyi & Stachniss 2016) on scans ray-cast here from known
// scenes: boxes and poles on a ground plane inside a walled yard, seen by a 32-ring sensor.
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/segmentation/segmenter.h"

#include <gtest/gtest.h>

#include "support/validation.h"

#include <cmath>
#include <map>
#include <stdexcept>
#include <string>

namespace segmatch {
namespace {

constexpr float kGroundZ = -1.73f;  // the sensor is at the origin, 1.73 m above the ground
constexpr uint32_t kGround = 0, kWalls = 99;

struct Box {
  Eigen::Vector3f lo, hi;
  uint32_t label;
};
struct Pole {
  float x, y, radius, top;
  uint32_t label;
};

struct World {
  std::vector<Box> boxes;
  std::vector<Pole> poles;
  World() {  // the yard: four walls 40 m out, 6 m high
    for (int s = -1; s <= 1; s += 2) {
      boxes.push_back({{40.f * s - 0.5f, -40.5f, kGroundZ}, {40.f * s + 0.5f, 40.5f, 4.f}, kWalls});
      boxes.push_back({{-40.5f, 40.f * s - 0.5f, kGroundZ}, {40.5f, 40.f * s + 0.5f, 4.f}, kWalls});
    }
  }
  void box(float x0, float y0, float x1, float y1, float top, uint32_t label) {
    boxes.push_back({{x0, y0, kGroundZ}, {x1, y1, top}, label});
  }
};

// Distance along the ray o + t d (d unit) to the first surface hit, and its label.
bool hit_box(const Box& b, const Eigen::Vector3f& o, const Eigen::Vector3f& d, float* t) {
  float t0 = 0.f, t1 = 1e9f;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-9f) {
      if (o[a] < b.lo[a] || o[a] > b.hi[a]) return false;
      continue;
    }
    float ta = (b.lo[a] - o[a]) / d[a], tb = (b.hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta), t1 = std::min(t1, tb);
  }
  *t = t0;
  return t0 <= t1 && t0 > 0.f;
}
bool hit_pole(const Pole& p, const Eigen::Vector3f& o, const Eigen::Vector3f& d, float* t) {
  const float dx = o.x() - p.x, dy = o.y() - p.y;
  const float a = d.x() * d.x() + d.y() * d.y(), b = 2.f * (dx * d.x() + dy * d.y());
  const float disc = b * b - 4.f * a * (dx * dx + dy * dy - p.radius * p.radius);
  if (a < 1e-12f || disc < 0.f) return false;
  *t = (-b - std::sqrt(disc)) / (2.f * a);
  const float z = o.z() + *t * d.z();
  return *t > 0.f && z >= kGroundZ && z <= p.top;
}

struct Scan {
  PointCloud cloud;
  std::vector<uint32_t> labels;
  PointCloud without_ground() const {
    PointCloud out;
    for (size_t i = 0; i < cloud.size(); ++i)
      if (labels[i] != kGround) out.push_back(cloud[i]);
    return out;
  }
  std::vector<uint32_t> labels_without_ground() const {
    std::vector<uint32_t> out;
    for (uint32_t l : labels)
      if (l != kGround) out.push_back(l);
    return out;
  }
};

// 32 rings from -15 to +15 deg (0.97 deg apart), 1800 columns (0.2 deg), 100 m, tilted by R.
Scan scan_of(const World& w, const Eigen::Matrix3f& R = Eigen::Matrix3f::Identity()) {
  Scan s;
  const Eigen::Vector3f o = Eigen::Vector3f::Zero();
  for (int ring = 0; ring < 32; ++ring) {
    const double e = (-15.0 + 30.0 * ring / 31.0) * M_PI / 180.0;
    for (int c = 0; c < 1800; ++c) {
      const double a = (0.1 + 0.2 * c) * M_PI / 180.0;  // firings between the columns' edges
      const Eigen::Vector3f d =
          R * Eigen::Vector3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e)).cast<float>();
      float best = 100.f, t;
      uint32_t label = UINT32_MAX;
      if (d.z() < 0.f && (t = (kGroundZ - o.z()) / d.z()) < best) best = t, label = kGround;
      for (const Box& b : w.boxes)
        if (hit_box(b, o, d, &t) && t < best) best = t, label = b.label;
      for (const Pole& p : w.poles)
        if (hit_pole(p, o, d, &t) && t < best) best = t, label = p.label;
      if (label == UINT32_MAX) continue;
      const Eigen::Vector3f p = o + best * d;
      s.cloud.push_back({p.x(), p.y(), p.z(), 0.f});
      s.labels.push_back(label);
    }
  }
  return s;
}

SegmenterConfig range_image() {
  SegmenterConfig c;
  c.type = SegmenterType::kRangeImage;
  c.min_points = 10;
  c.max_points = 1000000;
  return c;
}

// Segments of the scan's ground-free points straight from the range image (no voxels).
Segments segment_scan(const Scan& s, const SegmenterConfig& c) {
  const RangeImageGrid grid = fit_range_image(s.cloud, Eigen::Vector3f::Zero(), c);
  EXPECT_TRUE(grid.valid());
  if (!grid.valid()) return {};
  const PointCloud foreground = s.without_ground();
  const std::vector<uint32_t> labels = s.labels_without_ground();
  return segments_of_components(foreground, range_image_components(grid, foreground, c), c, &labels);
}

// label -> {segments with that majority label, the points of the largest, points of that label}
struct Tally {
  std::map<uint32_t, int> segments;
  std::map<uint32_t, size_t> largest, total;
};
Tally tally(const Segments& segments, const std::vector<uint32_t>& point_labels) {
  Tally t;
  for (const Segment& s : segments) {
    ++t.segments[s.label];
    t.largest[s.label] = std::max(t.largest[s.label], s.points.size());
  }
  for (uint32_t l : point_labels) ++t.total[l];
  return t;
}

World objects() {
  World w;
  w.box(6.f, 6.f, 8.f, 7.f, 0.f, 1);              // a car-sized box at 45 deg
  w.poles.push_back({-5.f, 3.f, 0.15f, 2.f, 2});  // a pole
  w.box(-9.f, -5.f, -7.f, -3.f, 1.f, 3);
  w.poles.push_back({2.f, -9.f, 0.2f, 3.f, 4});
  w.box(-1.f, 12.f, 1.f, 16.f, 0.5f, 5);
  return w;
}

TEST(RangeImage, SeparatedObjectsGiveOneSegmentEach) {
  const Scan s = scan_of(objects());
  const RangeImageGrid grid = fit_range_image(s.cloud, Eigen::Vector3f::Zero(), range_image());
  EXPECT_TRUE(grid.rings);
  EXPECT_EQ(grid.rows(), 32);
  EXPECT_EQ(grid.columns, 1800);
  const Segments segments = segment_scan(s, range_image());
  const Tally t = tally(segments, s.labels_without_ground());
  for (uint32_t label = 1; label <= 5; ++label) {
    EXPECT_EQ(t.segments.count(label) ? t.segments.at(label) : 0, 1) << "object " << label;
    EXPECT_EQ(t.largest.at(label), t.total.at(label)) << "object " << label << " not whole";
  }
  // The walls are cut where a pole hides their whole height; nothing else is a segment.
  EXPECT_GE(t.segments.at(kWalls), 1);
  EXPECT_EQ(segments.size(), 5u + size_t(t.segments.at(kWalls)));
}

// A pillar 0.4 m in front of a wall: closer than the cluster distance (Euclidean merges them), but
// across the pillar's edges the range jumps at an angle beta of ~6 deg, below the paper's 10. The
// pillar hides the wall's whole height, so the wall is seen in two pieces.
World pillar_before_wall() {
  World w;
  w.box(12.f, -4.f, 12.3f, 4.f, 0.5f, 6);    // the wall, lower than the sensor
  w.box(11.6f, -0.3f, 11.8f, 0.3f, 2.f, 7);  // the pillar, above it: no vertical edge between
  return w;
}

// Only the pillar's front face (x = 11.6) is seen; no other surface comes near it.
bool pure(const Segment& s) {
  size_t front = 0;
  for (const Point& p : s.points) front += std::abs(p.x - 11.6f) < 0.1f && std::abs(p.y) < 0.35f;
  return front == 0 || front == s.points.size();
}

TEST(RangeImage, BetaSeparatesObjectsCloseIn3DAtDifferentRanges) {
  const Scan s = scan_of(pillar_before_wall());
  SegmenterConfig euclidean = range_image();
  euclidean.type = SegmenterType::kEuclidean;
  euclidean.cluster_distance_m = 0.5f;
  const std::vector<uint32_t> labels = s.labels_without_ground();
  const Tally merged = tally(segment_cloud(s.without_ground(), euclidean, &labels), labels);
  EXPECT_EQ(merged.segments.count(7), 0u) << "Euclidean clustering should merge the pillar into the wall";

  const Segments segments = segment_scan(s, range_image());
  const Tally split = tally(segments, labels);
  EXPECT_EQ(split.segments.at(6), 2);
  EXPECT_EQ(split.segments.at(7), 1);
  EXPECT_EQ(split.largest.at(7), split.total.at(7));
  for (const Segment& seg : segments) EXPECT_TRUE(pure(seg)) << "segment " << seg.id;

  SegmenterConfig low_beta = range_image();  // the threshold is what separates them
  low_beta.range_image_beta_deg = 3.0f;
  EXPECT_EQ(tally(segment_scan(s, low_beta), labels).segments.count(7), 0u);
}

// Column 0 looks along +x: a box across the x axis lies on both ends of the range image.
TEST(RangeImage, AzimuthWrapsAroundAtTheSeam) {
  World w;
  w.box(8.f, -1.f, 9.f, 1.f, 0.f, 8);
  const Scan s = scan_of(w);
  const Tally t = tally(segment_scan(s, range_image()), s.labels_without_ground());
  EXPECT_EQ(t.segments.at(8), 1);
  EXPECT_EQ(t.largest.at(8), t.total.at(8));
}

// A scan in the frame of an earlier one, pitched 3 deg and rolled 2 deg: every ring spreads over
// +-3.6 deg of elevation, yet the fitted axis gives back the 32 rings and the same segments.
TEST(RangeImage, RecoversTheRingsOfATiltedScan) {
  const Eigen::Matrix3f R = (Eigen::AngleAxisf(3.f * float(M_PI) / 180.f, Eigen::Vector3f::UnitY()) *
                             Eigen::AngleAxisf(2.f * float(M_PI) / 180.f, Eigen::Vector3f::UnitX()))
                                .toRotationMatrix();
  const Scan s = scan_of(objects(), R);
  const RangeImageGrid grid = fit_range_image(s.cloud, Eigen::Vector3f::Zero(), range_image());
  ASSERT_TRUE(grid.rings);
  EXPECT_EQ(grid.rows(), 32);
  EXPECT_LT((grid.to_image.row(2).transpose() - R.col(2)).norm(), 0.05f * float(M_PI) / 180.f);
  const Tally t = tally(segment_scan(s, range_image()), s.labels_without_ground());
  for (uint32_t label = 1; label <= 5; ++label) {
    EXPECT_EQ(t.segments.count(label) ? t.segments.at(label) : 0, 1) << "object " << label;
    EXPECT_EQ(t.largest.at(label), t.total.at(label)) << "object " << label << " not whole";
  }
}

// The whole pipeline (extract_segments): ground removal and the voxel grid around the range image.
TEST(RangeImage, ExtractSegmentsCarriesComponentsThroughTheVoxelGrid) {
  const Scan s = scan_of(pillar_before_wall());
  SegmentationConfig c;
  c.ground.method = GroundRemoval::kHeightThreshold;
  c.ground.sensor_height_m = -kGroundZ;
  c.voxel.leaf_m = 0.1f;
  c.voxel.min_points_per_voxel = 1;
  c.segmenter = range_image();
  c.segmenter.cluster_distance_m = 0.5f;
  const Eigen::Vector3f sensor = Eigen::Vector3f::Zero();
  const Segments split = extract_segments(s.cloud, sensor, c, &s.labels);
  std::map<uint32_t, int> count;
  for (const Segment& seg : split) ++count[seg.label];
  EXPECT_EQ(count[6], 2);
  EXPECT_EQ(count[7], 1);
  for (const Segment& seg : split) EXPECT_TRUE(seg.has_eigen && pure(seg)) << "segment " << seg.id;
  c.segmenter.type = SegmenterType::kEuclidean;
  count.clear();
  for (const Segment& seg : extract_segments(s.cloud, sensor, c, &s.labels)) ++count[seg.label];
  EXPECT_EQ(count[7], 0);
}

// No rings (an accumulated cloud: scans from several places): clustered as kEuclidean, exactly.
TEST(RangeImage, CloudWithoutRingsIsClusteredAsEuclidean) {
  const World w = objects();
  PointCloud cloud;
  for (int k = 0; k < 4; ++k) {
    Scan s = scan_of(w, Eigen::AngleAxisf(0.3f * k, Eigen::Vector3f::UnitY()).toRotationMatrix());
    cloud.insert(cloud.end(), s.cloud.begin(), s.cloud.end());
  }
  const Eigen::Vector3f sensor(0.f, 0.f, 0.5f);
  EXPECT_FALSE(fit_range_image(cloud, sensor, range_image()).valid());
  SegmentationConfig c;
  c.segmenter = range_image();
  SegmentationConfig e = c;
  e.segmenter.type = SegmenterType::kEuclidean;
  const Segments a = extract_segments(cloud, sensor, c), b = extract_segments(cloud, sensor, e);
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) {
    ASSERT_EQ(a[k].points.size(), b[k].points.size());
    EXPECT_EQ(a[k].centroid, b[k].centroid);
    EXPECT_EQ(a[k].eigen, b[k].eigen);
  }
}

TEST(RangeImage, ValidationNamesTheField) {
  const auto message = [](const SegmenterConfig& c) { return test::validation_message(c); };
  SegmenterConfig c = range_image();
  EXPECT_EQ(message(c), "");
  for (const float beta : {0.f, -1.f, 90.f, NAN}) {
    c.range_image_beta_deg = beta;
    EXPECT_NE(message(c).find("range_image_beta_deg"), std::string::npos) << beta;
  }
  c = range_image();
  for (const int rows : {-1, 1025}) {
    c.range_image_rows = rows;
    EXPECT_NE(message(c).find("range_image_rows"), std::string::npos) << rows;
  }
  c = range_image();
  for (const float step : {-0.1f, 0.01f, 11.f, INFINITY}) {
    c.range_image_azimuth_step_deg = step;
    EXPECT_NE(message(c).find("range_image_azimuth_step_deg"), std::string::npos) << step;
  }
  EXPECT_THROW(fit_range_image({{1.f, 0.f, 0.f, 0.f}}, Eigen::Vector3f::Zero(), c), std::invalid_argument);
  EXPECT_THROW(segments_of_components({{1.f, 0.f, 0.f, 0.f}}, {}, range_image()), std::invalid_argument);
}

// Rows of equal height for a sensor without rings: forced, any cloud has a grid.
TEST(RangeImage, UniformRowsNeedNoRings) {
  SegmenterConfig c = range_image();
  c.range_image_rows = 32;
  const Scan s = scan_of(objects());
  const RangeImageGrid grid = fit_range_image(s.cloud, Eigen::Vector3f::Zero(), c);
  ASSERT_TRUE(grid.valid());
  EXPECT_FALSE(grid.rings);
  EXPECT_EQ(grid.rows(), 32);
  EXPECT_NEAR(grid.azimuth_step_deg, grid.row_bounds_deg[1] - grid.row_bounds_deg[0], 0.01f);
}

}  // namespace
}  // namespace segmatch
