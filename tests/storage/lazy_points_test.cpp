// MapReader::load_segments_without_points / read_points and LazyPoints: the same points as a
// full load, a bounded cache, and a damaged point row named when it is read.
#include "storage_test_util.h"

#include <segmatch/storage/lazy_points.h>

#include <cstring>

namespace segmatch {
namespace storage {
namespace test {
namespace {

bool same_points(const PointCloud& a, const PointCloud& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Point)) == 0);
}

TEST(StorageLazyPoints, DescriptorsWithoutPointsAndPointsOnDemand) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(200, 41));
  const MapReader reader = MapReader::open(path);
  std::vector<uint32_t> k_full, k_light;
  const Segments full = reader.load_segments(&k_full), light = reader.load_segments_without_points(&k_light);
  ASSERT_EQ(full.size(), light.size());
  EXPECT_EQ(k_full, k_light);
  for (size_t i = 0; i < full.size(); ++i) {
    EXPECT_TRUE(light[i].points.empty());
    EXPECT_EQ(full[i].id, light[i].id);
    EXPECT_EQ(full[i].centroid, light[i].centroid);
    EXPECT_TRUE(full[i].eigen == light[i].eigen && full[i].esf == light[i].esf) << i;
    EXPECT_TRUE(same_points(full[i].points, reader.read_points(i))) << i;
  }
  EXPECT_THROW(reader.read_points(full.size()), StorageError);
}

TEST(StorageLazyPoints, CacheIsBoundedAndServesTheSamePoints) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  const Segments segments = random_segments(50, 43);
  write_test_map(path, segments);
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  const Segments full = reader->load_segments();
  size_t largest = 0;
  for (const Segment& s : full) largest = std::max(largest, s.points.size());
  const LazyPoints lazy(reader, 3 * largest);
  for (int pass = 0; pass < 2; ++pass) {
    for (size_t i : {0u, 1u, 2u, 0u, 7u, 0u}) {
      PointCloud out{Point{1, 2, 3, 4}};  // appended to, not replaced
      lazy.append(i, &out);
      ASSERT_EQ(out.size(), 1 + full[i].points.size());
      EXPECT_TRUE(same_points(PointCloud(out.begin() + 1, out.end()), full[i].points)) << i;
    }
    EXPECT_LE(lazy.stats().cached_points, 3 * largest);
  }
  const LazyPoints::Stats stats = lazy.stats();
  EXPECT_EQ(stats.reads + stats.hits, 12u);
  EXPECT_GE(stats.hits, 4u);  // segment 0 stays recent
  EXPECT_GE(stats.reads, 4u);
}

TEST(StorageLazyPoints, DamagedPointRowIsNamedWhenRead) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  const Segments segments = random_segments(30, 47);
  write_test_map(path, segments);
  std::string bytes = read_bytes(path);
  const std::string points = stored_blob(path, "SELECT points FROM segment_points WHERE row = 12");
  const size_t at = bytes.find(points.substr(0, 64));
  ASSERT_NE(at, std::string::npos);
  bytes[at + 50] ^= 0x01;
  write_bytes(path, bytes);
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  EXPECT_EQ(reader->load_segments_without_points().size(), 30u);  // the descriptors are intact
  const LazyPoints lazy(reader);
  PointCloud out;
  EXPECT_NO_THROW(lazy.append(10, &out));
  expect_storage_error([&] { lazy.append(11, &out); }, path, {"corrupted", "segment row 12", "points checksum"});
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
