// segments_near() returns exactly the segments a brute-force scan over centroids finds.
#include "storage_test_util.h"

namespace segmatch {
namespace storage {
namespace test {
namespace {

std::vector<uint64_t> brute_force(const Segments& all, const Eigen::Vector3f& center, float radius) {
  std::vector<uint64_t> ids;
  for (const Segment& s : all) {
    if ((s.centroid - center).squaredNorm() <= radius * radius) ids.push_back(s.id);
  }
  return ids;
}

std::vector<uint64_t> ids_of(const Segments& segments) {
  std::vector<uint64_t> ids;
  for (const Segment& s : segments) ids.push_back(s.id);
  return ids;
}

TEST(StorageSpatial, SegmentsNearEqualsBruteForce) {
  TempDir dir;
  const std::string path = dir.file("spatial.segmap");
  Segments segments = random_segments(2000, 21, 400.f, 1, 5);
  // Segments exactly on a query sphere's boundary and at the same centroid.
  for (int i = 0; i < 4; ++i) {
    segments[i].centroid = Eigen::Vector3f(10.f + 25.f * (i % 2), 10.f, 2.f);
  }
  write_test_map(path, segments);
  const MapReader reader = MapReader::open(path);

  std::mt19937 rng(4);
  std::uniform_real_distribution<float> where(-250.f, 250.f), radius(0.f, 120.f);
  size_t total = 0;
  for (int q = 0; q < 200; ++q) {
    const Eigen::Vector3f center(where(rng), where(rng), where(rng) * 0.02f);
    const float r = q % 20 == 0 ? 0.f : radius(rng);
    std::vector<uint32_t> keyframes;
    const Segments near = reader.segments_near(center, r, &keyframes);
    ASSERT_EQ(ids_of(near), brute_force(segments, center, r)) << "query " << q;
    ASSERT_EQ(keyframes.size(), near.size());
    total += near.size();
  }
  EXPECT_GT(total, 1000u);  // the queries were not all empty

  const Eigen::Vector3f on_boundary(10.f, 10.f, 2.f);
  EXPECT_EQ(ids_of(reader.segments_near(on_boundary, 25.f)), brute_force(segments, on_boundary, 25.f));
  EXPECT_EQ(reader.segments_near(on_boundary, 0.f).size(), 2u);
  EXPECT_EQ(reader.segments_near(on_boundary, 1e6f).size(), segments.size());
  EXPECT_TRUE(reader.segments_near(on_boundary, -1.f).empty());
  EXPECT_THROW(reader.segments_near({std::nanf(""), 0.f, 0.f}, 1.f), std::invalid_argument);
}

TEST(StorageSpatial, NearbySegmentsAreComplete) {
  TempDir dir;
  const std::string path = dir.file("near.segmap");
  const Segments segments = random_segments(300, 8, 100.f);
  write_test_map(path, segments);
  const MapReader reader = MapReader::open(path);
  const Segments all = reader.load_segments();
  const Segments near = reader.segments_near(segments[17].centroid, 30.f);
  // The same decoded segments as the full load, in the same (insertion) order.
  size_t j = 0;
  for (const Segment& s : near) {
    while (j < all.size() && all[j].id != s.id) ++j;
    ASSERT_LT(j, all.size());
    EXPECT_EQ(s.points.size(), all[j].points.size());
    EXPECT_EQ(std::memcmp(s.points.data(), all[j].points.data(), s.points.size() * sizeof(Point)), 0);
    EXPECT_TRUE(s.esf == all[j].esf);
  }
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
