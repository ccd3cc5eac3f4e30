// upgrade_map(): the stored schema-1 and schema-2 maps (maps/tiny-3, kept in the repository on
// purpose) rewritten in this build's schema decode to the same coordinates and eigen features
// bit for bit, ESF quantised as schema 3 stores it (intensity is not kept), and a damaged old
// map is refused untouched.
#include "storage_test_util.h"

#include <algorithm>
#include <cstring>
#include <filesystem>

namespace segmatch {
namespace storage {
namespace test {
namespace {

const std::string kOldMap = SEGMATCH_TINY3_MAP;  // maps/tiny-3/map.sqlite.tar.xz, unpacked at configure time
// The same map upgraded to schema 2 by the schema-2 build: lossless.
const std::string kSchemaTwoMap = SEGMATCH_SOURCE_DIR "/maps/tiny-3/map-schema2.sqlite";

enum class Esf { kExact, kQuantised };

void expect_bit_identical(const Segment& a, const Segment& b, Esf esf = Esf::kQuantised) {
  ASSERT_EQ(a.id, b.id);
  EXPECT_EQ(a.label, b.label);
  EXPECT_EQ(0, std::memcmp(a.centroid.data(), b.centroid.data(), sizeof(float) * 3)) << a.id;
  EXPECT_EQ(a.has_eigen, b.has_eigen);
  EXPECT_EQ(a.has_esf, b.has_esf);
  EXPECT_EQ(0, std::memcmp(a.eigen.data(), b.eigen.data(), sizeof(a.eigen))) << a.id;
  const EsfDescriptor expected_esf = esf == Esf::kExact ? a.esf : as_stored_esf(a.esf);
  EXPECT_EQ(0, std::memcmp(expected_esf.data(), b.esf.data(), sizeof(a.esf))) << a.id;
  ASSERT_EQ(a.points.size(), b.points.size()) << a.id;
  float lo = 0.f, hi = 0.f;
  for (size_t i = 0; i < a.points.size(); ++i) {
    lo = i ? std::min(lo, a.points[i].intensity) : a.points[i].intensity;
    hi = i ? std::max(hi, a.points[i].intensity) : a.points[i].intensity;
  }
  for (size_t i = 0; i < a.points.size(); ++i) {
    // x y z: the same bits; intensity: not kept since schema 2 (no stage of localization reads
    // it), the middle of the segment's range.
    ASSERT_EQ(0, std::memcmp(&a.points[i].x, &b.points[i].x, 3 * sizeof(float))) << a.id << " point " << i;
    ASSERT_NEAR(b.points[i].intensity, (hi + lo) / 2.f, (hi - lo) * 1e-4f + 1e-6f) << a.id;
  }
}

TEST(StorageUpgrade, SchemaOneMapComesBackBitForBit) {
  TempDir dir;
  const std::string upgraded = dir.file("upgraded.segmap");
  const MapReader old = MapReader::open(kOldMap);
  ASSERT_EQ(old.schema_version(), 1) << "maps/tiny-3 is the stored schema-1 map";
  EXPECT_EQ(upgrade_map(kOldMap, upgraded, false), 1);
  const MapReader now = MapReader::open(upgraded);
  EXPECT_EQ(now.schema_version(), kSchemaVersion);
  EXPECT_TRUE(now.check_integrity().empty());
  EXPECT_FALSE(old.surfaces());
  EXPECT_FALSE(now.surfaces()) << "an old map holds no scans to make a surface layer from";

  std::vector<uint32_t> old_keyframes, new_keyframes;
  const Segments before = old.load_segments(&old_keyframes), after = now.load_segments(&new_keyframes);
  ASSERT_EQ(before.size(), after.size());
  for (size_t i = 0; i < before.size(); ++i) expect_bit_identical(before[i], after[i]);
  EXPECT_EQ(old_keyframes, new_keyframes);
  const std::vector<Keyframe> t0 = old.trajectory(), t1 = now.trajectory();
  ASSERT_EQ(t0.size(), t1.size());
  for (size_t i = 0; i < t0.size(); ++i) EXPECT_EQ(t0[i].T_map_sensor.matrix(), t1[i].T_map_sensor.matrix());
  EXPECT_EQ(old.classifier()->bytes, now.classifier()->bytes);
  EXPECT_EQ(old.metadata().parameters_json, now.metadata().parameters_json);
  EXPECT_EQ(old.metadata().created_utc, now.metadata().created_utc);
  EXPECT_EQ(old.stats().points, now.stats().points);
  // The same segments near a point, read through the R*Tree of each file.
  const Eigen::Vector3f at = before[before.size() / 2].centroid;
  const Segments near0 = old.segments_near(at, 20.f), near1 = now.segments_near(at, 20.f);
  ASSERT_EQ(near0.size(), near1.size());
  for (size_t i = 0; i < near0.size(); ++i) expect_bit_identical(near0[i], near1[i]);
  std::printf("[upgrade] %zu segments: %.2f MB -> %.2f MB\n", before.size(), std::filesystem::file_size(kOldMap) / 1e6,
              std::filesystem::file_size(upgraded) / 1e6);
}

TEST(StorageUpgrade, SchemaTwoMapReadsAsItsOriginalAndUpgrades) {
  const MapReader v1 = MapReader::open(kOldMap), v2 = MapReader::open(kSchemaTwoMap);
  ASSERT_EQ(v2.schema_version(), 2) << "maps/tiny-3/map-schema2.sqlite is the stored schema-2 map";
  EXPECT_TRUE(v2.check_integrity().empty());
  const Segments original = v1.load_segments(), stored = v2.load_segments();
  ASSERT_EQ(original.size(), stored.size());
  for (size_t i = 0; i < original.size(); ++i) expect_bit_identical(original[i], stored[i], Esf::kExact);
  // Its points read one segment at a time, as a lazy server reads them.
  for (size_t i = 0; i < stored.size(); i += 17) {
    const PointCloud points = v2.read_points(i);
    ASSERT_EQ(points.size(), stored[i].points.size());
    EXPECT_EQ(0, std::memcmp(points.data(), stored[i].points.data(), points.size() * sizeof(Point)));
  }

  TempDir dir;
  const std::string upgraded = dir.file("upgraded.segmap");
  EXPECT_EQ(upgrade_map(kSchemaTwoMap, upgraded, false), 2);
  const MapReader now = MapReader::open(upgraded);
  EXPECT_EQ(now.schema_version(), kSchemaVersion);
  EXPECT_TRUE(now.check_integrity().empty());
  const Segments after = now.load_segments();
  ASSERT_EQ(original.size(), after.size());
  for (size_t i = 0; i < original.size(); ++i) expect_bit_identical(original[i], after[i]);
  EXPECT_EQ(v1.classifier()->bytes, now.classifier()->bytes);
  std::printf("[upgrade] schema 2 -> %d: %.2f MB -> %.2f MB\n", kSchemaVersion,
              std::filesystem::file_size(kSchemaTwoMap) / 1e6, std::filesystem::file_size(upgraded) / 1e6);
}

TEST(StorageUpgrade, RefusesAMapAlreadyAtThisSchema) {
  TempDir dir;
  const std::string current = dir.file("current.segmap");
  write_test_map(current, random_segments(5, 3));
  expect_storage_error([&] { upgrade_map(current, dir.file("again.segmap"), false); }, current,
                       {"already at schema", "nothing to upgrade"});
  EXPECT_FALSE(std::filesystem::exists(dir.file("again.segmap")));
}

TEST(StorageUpgrade, DamagedOldMapIsRefusedAndNothingIsWritten) {
  TempDir dir;
  const std::string damaged = dir.file("damaged-v1.segmap");
  std::string bytes = read_bytes(kOldMap);
  const std::string esf = stored_blob(kOldMap, "SELECT esf FROM segments WHERE row = 50");
  ASSERT_EQ(esf.size(), sizeof(EsfDescriptor));
  // Schema 1 stores ESF as raw floats: find a stretch of them that is not all zero bins.
  size_t offset = 0;
  while (offset + 64 < esf.size() && esf.substr(offset, 64) == std::string(64, '\0')) offset += 64;
  const size_t at = bytes.find(esf.substr(offset, 64));
  ASSERT_NE(at, std::string::npos);
  bytes[at + 10] ^= 0x20;
  write_bytes(damaged, bytes);
  const std::vector<std::string> before = dir.entries();
  const std::string target = dir.file("upgraded.segmap");
  expect_storage_error([&] { upgrade_map(damaged, target, false); }, damaged, {"corrupted", "segment row 50"});
  EXPECT_EQ(dir.entries(), before) << "no new map and no temporary file";
  EXPECT_EQ(read_bytes(damaged), bytes) << "the old map is left as it was";
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
