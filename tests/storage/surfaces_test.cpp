// The surface layer (schema 4): tiles round-trip within the stated error (map_writer.h), near()
// returns what a brute-force search over the decoded tiles returns, from any number of threads;
// a damaged tile is refused by name; maps without a layer (older schemas, upgraded ones, maps
// written without set_surfaces) say so.
#include "storage_test_util.h"

#include <segmatch/storage/lazy_surfaces.h>

#include <sqlite3.h>

#include <cmath>
#include <cstring>
#include <map>
#include <thread>
#include <tuple>

namespace segmatch {
namespace storage {
namespace test {
namespace {

const std::string kSchemaOneMap = SEGMATCH_TINY3_MAP;
const std::string kSchemaTwoMap = SEGMATCH_SOURCE_DIR "/maps/tiny-3/map-schema2.sqlite";

// The bound of map_writer.h: 5 mm, plus one float rounding of the coordinate.
bool within_error(float stored, float decoded) {
  return std::fabs(double(stored) - double(decoded)) <= 0.005 + 1e-7 + std::fabs(stored) * 6e-8;
}
bool within_error(const Point& a, const Point& b) {
  return within_error(a.x, b.x) && within_error(a.y, b.y) && within_error(a.z, b.z);
}

std::pair<int32_t, int32_t> tile_of(const Point& p, float tile_m) {
  return {int32_t(std::floor(double(p.x) / tile_m)), int32_t(std::floor(double(p.y) / tile_m))};
}

// Random ground-and-wall-like points over [-half, half)^2, heights 0..12 m, and points on and
// next to the tile borders (negative ones included).
PointCloud random_surfaces(size_t n, uint32_t seed, float half, float tile_m) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> where(-half, half), height(0.f, 12.f);
  PointCloud points;
  for (size_t i = 0; i < n; ++i) points.push_back({where(rng), where(rng), height(rng), 0.5f});
  for (int k = -3; k <= 3; ++k) {
    const float border = float(k) * tile_m;
    for (float d : {0.f, 1e-4f, -1e-4f, 0.004f, -0.004f}) {
      points.push_back({border + d, where(rng), height(rng), 0.f});
      points.push_back({where(rng), border + d, height(rng), 0.f});
      points.push_back({border + d, border - d, height(rng), 0.f});
    }
  }
  return points;
}

void write_surface_map(const std::string& path, const PointCloud& surfaces, float leaf_m, float tile_m) {
  MapWriter writer = MapWriter::create(path, test_metadata(), false);
  writer.add_segments(random_segments(5, 3), {});
  writer.set_surfaces(surfaces, leaf_m, tile_m);
  writer.commit();
}

PointCloud all_decoded(const MapReader& reader) {
  PointCloud out;
  for (const auto& [x, y] : reader.surface_tile_keys()) {
    const PointCloud tile = reader.surface_tile(x, y);
    out.insert(out.end(), tile.begin(), tile.end());
  }
  return out;
}

PointCloud sorted(PointCloud points) {
  std::sort(points.begin(), points.end(),
            [](const Point& a, const Point& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
  return points;
}

bool same_points(const PointCloud& a, const PointCloud& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Point)) == 0);
}

// The brute-force answer: every decoded point within radius of center horizontally.
PointCloud oracle(const PointCloud& decoded, const Eigen::Vector3d& center, double radius) {
  PointCloud out;
  for (const Point& p : decoded) {
    const double dx = double(p.x) - center.x(), dy = double(p.y) - center.y();
    if (dx * dx + dy * dy <= radius * radius) out.push_back(p);
  }
  return out;
}

// Flips one byte of tile (x, y)'s BLOB in place, with SQLite itself.
void flip_tile_byte(const std::string& path, int x, int y, size_t at) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  const char* select = "SELECT points FROM surface_tiles WHERE tile_x = ? AND tile_y = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, select, -1, &st, nullptr), SQLITE_OK);
  sqlite3_bind_int(st, 1, x);
  sqlite3_bind_int(st, 2, y);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  std::string blob(static_cast<const char*>(sqlite3_column_blob(st, 0)), sqlite3_column_bytes(st, 0));
  sqlite3_finalize(st);
  ASSERT_LT(at, blob.size());
  blob[at] ^= 0x10;
  const char* update = "UPDATE surface_tiles SET points = ? WHERE tile_x = ? AND tile_y = ?";
  ASSERT_EQ(sqlite3_prepare_v2(db, update, -1, &st, nullptr), SQLITE_OK);
  sqlite3_bind_blob(st, 1, blob.data(), int(blob.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int(st, 2, x);
  sqlite3_bind_int(st, 3, y);
  EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
  sqlite3_finalize(st);
  sqlite3_close(db);
}

TEST(StorageSurfaces, TilesRoundTripWithinTheStatedError) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  const float tile_m = 20.f;
  PointCloud points = random_surfaces(6000, 11, 65.f, tile_m);
  // One tile whose heights span more than int16 at 1 cm holds: stored as float32, exactly.
  points.push_back({-35.f, 45.f, -500.f, 0.f});
  points.push_back({-35.5f, 45.5f, 500.f, 0.f});
  write_surface_map(path, points, 0.25f, tile_m);

  std::map<std::pair<int32_t, int32_t>, PointCloud> expected;
  for (const Point& p : points) expected[tile_of(p, tile_m)].push_back(p);
  const MapReader reader = MapReader::open(path);
  EXPECT_EQ(reader.schema_version(), 4);
  ASSERT_TRUE(reader.surfaces());
  const SurfaceLayer layer = *reader.surfaces();
  EXPECT_EQ(layer.leaf_m, 0.25f);
  EXPECT_EQ(layer.tile_m, tile_m);
  EXPECT_EQ(layer.tile_count, expected.size());
  EXPECT_EQ(layer.point_count, points.size());
  EXPECT_GT(layer.stored_bytes, 0u);
  EXPECT_LT(layer.stored_bytes, points.size() * 6) << "int16 x y z at most, before zstd";
  const auto keys = reader.surface_tile_keys();
  ASSERT_EQ(keys.size(), expected.size());
  for (const auto& [key, originals] : expected) {
    ASSERT_TRUE(std::binary_search(keys.begin(), keys.end(), key)) << key.first << ", " << key.second;
    const PointCloud decoded = reader.surface_tile(key.first, key.second);
    ASSERT_EQ(decoded.size(), originals.size()) << key.first << ", " << key.second;
    // Every original comes back within the error and every decoded point is one of them.
    for (const Point& o : originals)
      EXPECT_TRUE(std::any_of(decoded.begin(), decoded.end(), [&](const Point& d) { return within_error(o, d); }))
          << "tile " << key.first << ", " << key.second << ": " << o.x << " " << o.y << " " << o.z << " lost";
    for (const Point& d : decoded) {
      EXPECT_TRUE(std::any_of(originals.begin(), originals.end(), [&](const Point& o) { return within_error(o, d); }));
      EXPECT_EQ(d.intensity, 0.f);
    }
  }
  const PointCloud spread = reader.surface_tile(-2, 2);
  ASSERT_EQ(spread.size(), expected[std::make_pair(-2, 2)].size());
  EXPECT_TRUE(std::any_of(spread.begin(), spread.end(), [](const Point& p) { return p.z == -500.f && p.x == -35.f; }));
  EXPECT_TRUE(reader.surface_tile(1000, -1000).empty());
  EXPECT_TRUE(reader.check_integrity().empty());
}

TEST(StorageSurfaces, NearMatchesABruteForceSearch) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_surface_map(path, random_surfaces(30000, 13, 200.f, 25.f), 0.25f, 25.f);
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  const PointCloud decoded = all_decoded(*reader);
  ASSERT_EQ(decoded.size(), reader->surfaces()->point_count);
  const std::shared_ptr<const MapSurfaces> surfaces = make_lazy_surfaces(reader);
  ASSERT_TRUE(surfaces);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> where(-220.0, 220.0);
  std::vector<Eigen::Vector3d> centres = {{0, 0, 0}, {25, -50, 3}, {-0.001, 24.999, -7}};
  for (int i = 0; i < 6; ++i) centres.emplace_back(where(rng), where(rng), where(rng));
  for (const Eigen::Vector3d& c : centres) {
    for (double radius : {0.0, 0.3, 7.5, 40.0, 160.0, 2000.0}) {  // 2000 m: every tile
      const PointCloud got = surfaces->near(c, radius), want = oracle(decoded, c, radius);
      EXPECT_TRUE(same_points(sorted(got), sorted(want)))
          << c.transpose() << " r " << radius << ": " << got.size() << " points, expected " << want.size();
    }
  }
  EXPECT_EQ(surfaces->near({0, 0, 0}, 2000.0).size(), decoded.size());
  // A disc touching no tile reads nothing.
  const auto& lazy = static_cast<const LazySurfaces&>(*surfaces);
  const LazySurfaces::Stats before = lazy.stats();
  EXPECT_TRUE(surfaces->near({5000, -5000, 0}, 100.0).empty());
  EXPECT_TRUE(surfaces->near({0, 0, 0}, -1.0).empty());
  EXPECT_EQ(lazy.stats().reads + lazy.stats().hits, before.reads + before.hits);
  EXPECT_THROW(surfaces->near({NAN, 0, 0}, 1.0), std::invalid_argument);
}

TEST(StorageSurfaces, ThreadsGetWhatOneThreadGets) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_surface_map(path, random_surfaces(20000, 17, 150.f, 20.f), 0.25f, 20.f);
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  std::vector<Eigen::Vector3d> centres;
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> where(-160.0, 160.0);
  for (int i = 0; i < 40; ++i) centres.emplace_back(where(rng), where(rng), 0.0);
  const LazySurfaces serial(reader);
  std::vector<PointCloud> expected;
  for (const auto& c : centres) expected.push_back(serial.near(c, 35.0));
  const LazySurfaces shared(reader, 3000);  // small: tiles are evicted and read again meanwhile
  std::vector<std::thread> threads;
  std::vector<int> mismatches(6, 0);
  for (int t = 0; t < 6; ++t) {
    threads.emplace_back([&, t] {
      for (int pass = 0; pass < 3; ++pass)
        for (size_t i = (t * 7) % centres.size(), k = 0; k < centres.size(); ++k, i = (i + 1) % centres.size())
          mismatches[t] += !same_points(shared.near(centres[i], 35.0), expected[i]);
    });
  }
  for (std::thread& t : threads) t.join();
  for (int t = 0; t < 6; ++t) EXPECT_EQ(mismatches[t], 0) << "thread " << t;
  const LazySurfaces::Stats stats = shared.stats();
  EXPECT_LE(stats.cached_points, 3000u);
  EXPECT_GT(stats.reads, 0u);
  EXPECT_GT(stats.hits, 0u);
}

TEST(StorageSurfaces, DamagedTileIsRefusedNamingIt) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_surface_map(path, random_surfaces(4000, 19, 50.f, 20.f), 0.25f, 20.f);
  flip_tile_byte(path, -1, 1, 40);
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  EXPECT_FALSE(reader->surface_tile(0, 0).empty()) << "the other tiles are intact";
  expect_storage_error([&] { reader->surface_tile(-1, 1); }, path, {"corrupted", "surface tile (-1, 1)", "checksum"});
  const LazySurfaces surfaces(reader);
  expect_storage_error([&] { surfaces.near({-10, 30, 0}, 5.0); }, path, {"surface tile (-1, 1)"});
  const std::vector<std::string> problems = reader->check_integrity();
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("surface tile (-1, 1)"), std::string::npos) << problems[0];
}

TEST(StorageSurfaces, MapWrittenWithoutALayerHasNone) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(20, 23));
  auto reader = std::make_shared<const MapReader>(MapReader::open(path));
  EXPECT_EQ(reader->schema_version(), kSchemaVersion);
  EXPECT_FALSE(reader->surfaces());
  EXPECT_TRUE(reader->surface_tile(0, 0).empty());
  EXPECT_TRUE(reader->surface_tile_keys().empty());
  EXPECT_EQ(make_lazy_surfaces(reader), nullptr);
  EXPECT_THROW(LazySurfaces{reader}, std::invalid_argument);
  EXPECT_TRUE(reader->check_integrity().empty());
}

TEST(StorageSurfaces, SchemaThreeMapHasNoLayerAndUpgradesWithout) {
  TempDir dir;
  const std::string old_path = dir.file("schema3.segmap"), new_path = dir.file("schema4.segmap");
  write_test_map(old_path, random_segments(40, 29));
  {  // What a schema-3 build wrote: the same tables without the surface layer's.
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(old_path.c_str(), &db), SQLITE_OK);
    EXPECT_EQ(sqlite3_exec(db, "DROP TABLE surface_tiles; DROP TABLE surface_layer; PRAGMA user_version = 3", nullptr,
                           nullptr, nullptr),
              SQLITE_OK);
    sqlite3_close(db);
  }
  auto old_map = std::make_shared<const MapReader>(MapReader::open(old_path));
  ASSERT_EQ(old_map->schema_version(), 3);
  EXPECT_FALSE(old_map->surfaces());
  EXPECT_TRUE(old_map->surface_tile(0, 0).empty());
  EXPECT_EQ(make_lazy_surfaces(old_map), nullptr);
  EXPECT_TRUE(old_map->check_integrity().empty());
  EXPECT_EQ(upgrade_map(old_path, new_path, false), 3);
  const MapReader upgraded = MapReader::open(new_path);
  EXPECT_EQ(upgraded.schema_version(), 4);
  EXPECT_FALSE(upgraded.surfaces());
  EXPECT_EQ(upgraded.load_segments().size(), 40u);
  EXPECT_TRUE(upgraded.check_integrity().empty());
  for (const std::string& stored : {kSchemaOneMap, kSchemaTwoMap}) {
    const MapReader map = MapReader::open(stored);
    EXPECT_LT(map.schema_version(), 3) << stored;
    EXPECT_FALSE(map.surfaces()) << stored;
    EXPECT_TRUE(map.surface_tile_keys().empty()) << stored;
  }
}

TEST(StorageSurfaces, InvalidArgumentsAreRefusedAndASecondCallReplaces) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  MapWriter writer = MapWriter::create(path, test_metadata(), false);
  const auto refused = [&](const PointCloud& points, float leaf, float tile, const std::string& word) {
    try {
      writer.set_surfaces(points, leaf, tile);
      ADD_FAILURE() << "accepted: " << word;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
    }
  };
  const PointCloud good = {{1, 2, 3, 0}, {-4, 5, 6, 0}};
  refused({{1, 2, 3, 0}, {1, NAN, 3, 0}}, 0.25f, 20.f, "point 1 is not finite");
  refused({{INFINITY, 2, 3, 0}}, 0.25f, 20.f, "point 0 is not finite");
  refused(good, 0.f, 20.f, "leaf_m");
  refused(good, 0.25f, -20.f, "tile_m");
  refused(good, 0.25f, NAN, "tile_m");
  refused({{1e30f, 0, 0, 0}}, 0.25f, 1.f, "beyond the tile grid");
  writer.set_surfaces(random_surfaces(500, 31, 30.f, 10.f), 0.25f, 10.f);
  writer.set_surfaces(good, 0.5f, 8.f);  // replaces the first
  writer.commit();
  const MapReader reader = MapReader::open(path);
  ASSERT_TRUE(reader.surfaces());
  EXPECT_EQ(reader.surfaces()->point_count, 2u);
  EXPECT_EQ(reader.surfaces()->tile_count, 2u);
  EXPECT_EQ(reader.surfaces()->leaf_m, 0.5f);
  EXPECT_EQ(reader.surfaces()->tile_m, 8.f);
  EXPECT_EQ(reader.surface_tile(-1, 0).size(), 1u);
  EXPECT_TRUE(reader.check_integrity().empty());
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
