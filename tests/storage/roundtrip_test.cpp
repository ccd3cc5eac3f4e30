// Everything written comes back: metadata, segments (ids, centroids, descriptors, labels,
// keyframes, points within the documented quantisation), trajectory, classifier, stats.
#include "storage_test_util.h"

#include <cmath>
#include <cstring>
#include <limits>

namespace segmatch {
namespace storage {
namespace test {
namespace {

// The bound of map_writer.h: half a step per axis, plus float rounding of the result.
float step_for(const Segment& s) {
  Eigen::Vector3f lo = s.points[0].xyz(), hi = lo;
  for (const Point& p : s.points) {
    lo = lo.cwiseMin(p.xyz());
    hi = hi.cwiseMax(p.xyz());
  }
  const float half_extent = ((hi - lo) * 0.5f).maxCoeff();
  return half_extent < 65.f ? 0.002f : half_extent < 327.f ? 0.01f : 0.f;
}

void expect_points_near(const Segment& original, const Segment& loaded) {
  ASSERT_EQ(original.points.size(), loaded.points.size()) << "segment " << original.id;
  if (original.points.empty()) return;
  const float step = step_for(original);
  float imin = original.points[0].intensity, imax = imin;
  for (const Point& p : original.points) {
    imin = std::min(imin, p.intensity);
    imax = std::max(imax, p.intensity);
  }
  for (size_t i = 0; i < original.points.size(); ++i) {
    const Point& a = original.points[i];
    const Point& b = loaded.points[i];
    const float xyz_tol = step / 2 * 1.0001f + 1.2e-7f * (1.f + a.xyz().cwiseAbs().maxCoeff());
    ASSERT_NEAR(a.x, b.x, xyz_tol) << "segment " << original.id << " point " << i;
    ASSERT_NEAR(a.y, b.y, xyz_tol);
    ASSERT_NEAR(a.z, b.z, xyz_tol);
    // Schema 2 does not keep the intensity of int16 points: it decodes to the middle of the
    // segment's range (exact when all are equal).
    ASSERT_NEAR(a.intensity, b.intensity, (imax - imin) / 2.f * 1.01f + 1e-6f * (1.f + std::abs(a.intensity)));
  }
}

void expect_segment_equal(const Segment& a, const Segment& b) {
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(a.label, b.label);
  EXPECT_EQ(a.centroid, b.centroid);  // exact
  EXPECT_EQ(a.has_eigen, b.has_eigen);
  EXPECT_EQ(a.has_esf, b.has_esf);
  if (a.has_eigen) {
    EXPECT_TRUE(a.eigen == b.eigen) << "eigen of " << a.id;
  }
  if (a.has_esf) {
    EXPECT_TRUE(as_stored_esf(a.esf) == b.esf) << "esf of " << a.id;  // quantised, bit for bit
  }
  expect_points_near(a, b);
}

TEST(StorageRoundTrip, EveryFieldComesBack) {
  TempDir dir;
  const std::string path = dir.file("city.segmap");
  const Segments segments = random_segments(300, 11);
  write_test_map(path, segments);

  const MapReader reader = MapReader::open(path);
  const MapMetadata& m = reader.metadata();
  const MapMetadata expected = test_metadata();
  EXPECT_EQ(m.name, expected.name);
  EXPECT_EQ(m.frame, expected.frame);
  EXPECT_EQ(m.created_utc, expected.created_utc);
  EXPECT_EQ(m.tool_version, expected.tool_version);
  EXPECT_EQ(m.parameters_json, expected.parameters_json);
  EXPECT_EQ(m.eigen_dims, kEigenFeatureCount);
  EXPECT_EQ(m.esf_dims, kEsfBins);
  EXPECT_EQ(reader.schema_version(), kSchemaVersion);

  std::vector<uint32_t> keyframes;
  const Segments loaded = reader.load_segments(&keyframes);
  ASSERT_EQ(loaded.size(), segments.size());
  ASSERT_EQ(keyframes.size(), segments.size());
  for (size_t i = 0; i < segments.size(); ++i) {
    expect_segment_equal(segments[i], loaded[i]);
    EXPECT_EQ(keyframes[i], uint32_t(i % 10) * 2);
  }

  const std::vector<Keyframe> trajectory = reader.trajectory();
  const std::vector<Keyframe> expected_trajectory = random_trajectory(10, 7);
  ASSERT_EQ(trajectory.size(), expected_trajectory.size());
  double length = 0;
  for (size_t i = 0; i < trajectory.size(); ++i) {
    EXPECT_EQ(trajectory[i].index, expected_trajectory[i].index);
    EXPECT_EQ(trajectory[i].time_s, expected_trajectory[i].time_s);
    EXPECT_TRUE(trajectory[i].T_map_sensor.matrix() == expected_trajectory[i].T_map_sensor.matrix())
        << "pose " << i << " not bit-exact";
    if (i) {
      length +=
          (expected_trajectory[i].T_map_sensor.translation() - expected_trajectory[i - 1].T_map_sensor.translation())
              .norm();
    }
  }

  const std::optional<ClassifierBlob> classifier = reader.classifier();
  ASSERT_TRUE(classifier.has_value());
  EXPECT_EQ(classifier->format, "test-format");
  EXPECT_EQ(classifier->bytes, std::string("\0model\xff bytes", 13));

  const MapStats stats = reader.stats();
  size_t points = 0;
  for (const Segment& s : segments) points += s.points.size();
  EXPECT_EQ(stats.segments, segments.size());
  EXPECT_EQ(stats.points, points);
  EXPECT_EQ(stats.keyframes, 10u);
  EXPECT_NEAR(stats.trajectory_length_m, length, 1e-9);
  EXPECT_TRUE(stats.has_classifier);
  EXPECT_TRUE(reader.check_integrity().empty());
}

TEST(StorageRoundTrip, EdgeCasesOfSegments) {
  TempDir dir;
  const std::string path = dir.file("edge.segmap");
  std::mt19937 rng(5);
  Segments segments;
  // Empty segment, extreme id and label, unknown keyframe.
  Segment empty;
  empty.id = std::numeric_limits<uint64_t>::max();
  empty.label = 0xFFFFFFFFu;
  empty.centroid = {1.5f, -2.25f, 3.f};
  segments.push_back(empty);
  // A 200 m wide segment (1 cm steps), a 1 km wide one (exact float32), far from the origin.
  segments.push_back(random_segment(rng, 2, {5000.f, -3000.f, 20.f}, 500, 100.f));
  segments.push_back(random_segment(rng, 3, {-8000.f, 9000.f, 0.f}, 500, 500.f));
  // Constant intensity (exact) and a non-finite value (stored as exact float32).
  Segment flat = random_segment(rng, 4, {0.f, 0.f, 0.f}, 50);
  for (Point& p : flat.points) p.intensity = 0.37f;
  segments.push_back(flat);
  Segment odd = random_segment(rng, 5, {10.f, 10.f, 0.f}, 10);
  odd.points[3].intensity = std::numeric_limits<float>::infinity();
  segments.push_back(odd);
  {
    MapWriter writer = MapWriter::create(path, test_metadata(), false);
    writer.add_segments({segments[0], segments[1]}, {});  // keyframes unknown
    writer.add_segments({segments[2], segments[3], segments[4]}, {kNoKeyframe, 42, 0});
    writer.commit();
  }
  const MapReader reader = MapReader::open(path);
  std::vector<uint32_t> keyframes;
  const Segments loaded = reader.load_segments(&keyframes);
  ASSERT_EQ(loaded.size(), segments.size());
  EXPECT_EQ(keyframes, (std::vector<uint32_t>{kNoKeyframe, kNoKeyframe, kNoKeyframe, 42, 0}));
  for (size_t i = 0; i < 4; ++i) expect_segment_equal(segments[i], loaded[i]);
  for (size_t i = 0; i < flat.points.size(); ++i) {
    EXPECT_EQ(loaded[3].points[i].intensity, 0.37f);
  }
  EXPECT_EQ(loaded[2].points[7].x, segments[2].points[7].x);  // float32 fallback is exact
  for (size_t i = 0; i < odd.points.size(); ++i) {
    EXPECT_EQ(std::memcmp(&odd.points[i], &loaded[4].points[i], sizeof(Point)), 0);
  }
  EXPECT_TRUE(reader.trajectory().empty());
  EXPECT_FALSE(reader.classifier().has_value());
  EXPECT_FALSE(reader.stats().has_classifier);
  EXPECT_TRUE(reader.check_integrity().empty());
}

// Enough rows for load_segments() to split the work over several threads and connections.
TEST(StorageRoundTrip, LargeMapLoadsInParallel) {
  TempDir dir;
  const std::string path = dir.file("large.segmap");
  const Segments segments = random_segments(9000, 17, 2000.f, 0, 4);
  write_test_map(path, segments);
  const MapReader reader = MapReader::open(path);
  std::vector<uint32_t> keyframes;
  const Segments loaded = reader.load_segments(&keyframes);
  ASSERT_EQ(loaded.size(), segments.size());
  for (size_t i = 0; i < segments.size(); ++i) {
    expect_segment_equal(segments[i], loaded[i]);
    ASSERT_EQ(keyframes[i], uint32_t(i % 10) * 2);
  }

  // A damaged row near the end (read by another thread than the caller's) still throws.
  std::string bytes = read_bytes(path);
  const std::string esf = stored_blob(path, "SELECT esf FROM segments WHERE row = 8991");
  ASSERT_GT(esf.size(), 48u);
  const size_t at = unique_stretch(bytes, esf);
  ASSERT_NE(at, std::string::npos);
  bytes[at + 30] ^= 0x10;
  const std::string damaged = dir.file("damaged.segmap");
  write_bytes(damaged, bytes);
  expect_storage_error([&] { MapReader::open(damaged).load_segments(); }, damaged,
                       {"corrupted", "segment row 8991", "checksum mismatch"});
}

TEST(StorageRoundTrip, EmptyMapAndDefaultCreationTime) {
  TempDir dir;
  const std::string path = dir.file("empty.segmap");
  MapMetadata metadata = test_metadata();
  metadata.created_utc.clear();
  MapWriter::create(path, metadata, false).commit();
  const MapReader reader = MapReader::open(path);
  const std::string& created = reader.metadata().created_utc;
  ASSERT_EQ(created.size(), 20u) << created;  // YYYY-MM-DDTHH:MM:SSZ
  EXPECT_EQ(created[4], '-');
  EXPECT_EQ(created[10], 'T');
  EXPECT_EQ(created.back(), 'Z');
  EXPECT_TRUE(reader.load_segments().empty());
  EXPECT_EQ(reader.stats().segments, 0u);
  EXPECT_TRUE(reader.check_integrity().empty());
}

TEST(StorageRoundTrip, ReplacingTrajectoryAndClassifier) {
  TempDir dir;
  const std::string path = dir.file("replace.segmap");
  MapWriter writer = MapWriter::create(path, test_metadata(), false);
  writer.set_trajectory(random_trajectory(5, 1));
  writer.set_trajectory(random_trajectory(3, 2));
  writer.set_classifier({"a", "first"});
  writer.set_classifier({"b", ""});
  writer.commit();
  const MapReader reader = MapReader::open(path);
  EXPECT_EQ(reader.trajectory().size(), 3u);
  EXPECT_EQ(reader.stats().keyframes, 3u);
  ASSERT_TRUE(reader.classifier().has_value());
  EXPECT_EQ(reader.classifier()->format, "b");
  EXPECT_EQ(reader.classifier()->bytes, "");
}

TEST(StorageRoundTrip, InvalidInputIsRefused) {
  TempDir dir;
  MapMetadata wrong_dims = test_metadata();
  wrong_dims.esf_dims = 308;
  EXPECT_THROW(MapWriter::create(dir.file("a.segmap"), wrong_dims, false), std::invalid_argument);
  EXPECT_TRUE(dir.entries().empty());

  MapWriter writer = MapWriter::create(dir.file("b.segmap"), test_metadata(), false);
  Segments two = random_segments(2, 3);
  EXPECT_THROW(writer.add_segments(two, {1}), std::invalid_argument);
  two[1].centroid.x() = std::nanf("");
  EXPECT_THROW(writer.add_segments(two, {}), std::invalid_argument);
  std::vector<Keyframe> twice = random_trajectory(2, 3);
  twice[1].index = twice[0].index;
  EXPECT_THROW(writer.set_trajectory(twice), std::invalid_argument);
  // Refused input left nothing behind: the writer still commits an empty map.
  writer.commit();
  EXPECT_EQ(MapReader::open(dir.file("b.segmap")).stats().segments, 0u);
  EXPECT_THROW(writer.commit(), std::logic_error);
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
