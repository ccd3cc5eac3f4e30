// Files that are not a readable segment map of this schema are refused with a StorageError
// that names the file and the problem.
#include "storage_test_util.h"

// The storage library links SQLite; the tests use it directly to forge databases.
#include <sqlite3.h>

#include <filesystem>

namespace segmatch {
namespace storage {
namespace test {
namespace {

// Fixed SQL on a scratch database (test-only; the library itself binds every value).
void run_sql(const std::string& path, const char* sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* error = nullptr;
  const int rc = sqlite3_exec(db, sql, nullptr, nullptr, &error);
  EXPECT_EQ(rc, SQLITE_OK) << (error ? error : "");
  sqlite3_free(error);
  sqlite3_close(db);
}

// Opens and reads every part; whatever is wrong must surface as a StorageError.
void read_everything(const std::string& path) {
  const MapReader reader = MapReader::open(path);
  reader.load_segments();
  reader.trajectory();
  reader.classifier();
  reader.stats();
}

class StorageRefusal : public ::testing::Test {
 public:  // expect_bit_flip_named reads the map's bytes
  void SetUp() override {
    path_ = dir_.file("good.segmap");
    write_test_map(path_, random_segments(300, 31));
    bytes_ = read_bytes(path_);
  }
  // A copy of the good map, changed by `edit`.
  std::string variant(const std::string& name, const std::function<void(std::string&)>& edit) {
    std::string bytes = bytes_;
    edit(bytes);
    const std::string path = dir_.file(name);
    write_bytes(path, bytes);
    return path;
  }

  TempDir dir_;
  std::string path_, bytes_;
};

TEST_F(StorageRefusal, GoodMapOpens) {
  EXPECT_NO_THROW(read_everything(path_));
  EXPECT_TRUE(MapReader::open(path_).check_integrity().empty());
}

TEST_F(StorageRefusal, NewerSchemaVersion) {
  const std::string path = variant("newer.segmap", [](std::string&) {});
  const std::string newer = std::to_string(kSchemaVersion + 1);
  run_sql(path, ("PRAGMA user_version = " + newer).c_str());
  expect_storage_error([&] { MapReader::open(path); }, path, {"schema version " + newer, "newer"});
}

TEST_F(StorageRefusal, OlderUnsupportedSchemaVersion) {
  const std::string path = variant("older.segmap", [](std::string&) {});
  run_sql(path, "PRAGMA user_version = 0");
  expect_storage_error([&] { MapReader::open(path); }, path, {"schema version 0", "older"});
}

TEST_F(StorageRefusal, ForeignSqliteDatabase) {
  const std::string path = dir_.file("foreign.db");
  run_sql(path, "CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)");
  expect_storage_error([&] { MapReader::open(path); }, path, {"another application", "application_id 0x00000000"});
  const std::string gpkg = dir_.file("other.gpkg");
  run_sql(gpkg, "PRAGMA application_id = 1196444487; CREATE TABLE t (x)");  // GeoPackage
  expect_storage_error([&] { MapReader::open(gpkg); }, gpkg, {"another application", "0x47504B47"});
}

TEST_F(StorageRefusal, OurIdButTablesMissing) {
  const std::string path = dir_.file("hollow.segmap");
  run_sql(path, "PRAGMA application_id = 1399278960; PRAGMA user_version = 1; CREATE TABLE t (x)");
  expect_storage_error([&] { MapReader::open(path); }, path, {"no table map_info"});
}

TEST_F(StorageRefusal, NotSqlite) {
  const std::string text = dir_.file("notes.segmap");
  write_bytes(text, std::string(5000, 'x'));
  expect_storage_error([&] { MapReader::open(text); }, text, {"not an SQLite database"});
  const std::string tiny = dir_.file("tiny.segmap");
  write_bytes(tiny, "SQLite");
  expect_storage_error([&] { MapReader::open(tiny); }, tiny, {"not an SQLite database"});
  const std::string empty = dir_.file("empty.segmap");
  write_bytes(empty, "");
  expect_storage_error([&] { MapReader::open(empty); }, empty, {"empty file"});
}

TEST_F(StorageRefusal, Truncated) {
  const std::string half = variant("half.segmap", [](std::string& b) { b.resize(b.size() / 2 + 100); });
  expect_storage_error([&] { MapReader::open(half); }, half, {"truncated"});
  const std::string page_short = variant("short.segmap", [](std::string& b) { b.resize(b.size() - 65536); });
  expect_storage_error([&] { MapReader::open(page_short); }, page_short, {"truncated", "header says"});
  const std::string header_only = variant("header.segmap", [](std::string& b) { b.resize(60); });
  expect_storage_error([&] { MapReader::open(header_only); }, header_only,
                       {"not an SQLite database", "truncated to 60 bytes"});
}

TEST_F(StorageRefusal, CorruptedInTheMiddle) {
  for (const size_t length : {16u, 256u, 4096u}) {
    const std::string path = variant("middle" + std::to_string(length) + ".segmap", [&](std::string& b) {
      for (size_t i = 0; i < length; ++i) b[b.size() / 2 + i] ^= 0x5A;
    });
    expect_storage_error([&] { read_everything(path); }, path, {"corrupted"});
    EXPECT_FALSE(MapReader::open(path).check_integrity().empty());
  }
}

// Flips one bit in the stored bytes of segment row `row`'s BLOB that `sql` selects (in a stretch
// found by unique_stretch()), then expects a full load to fail with `words`, the integrity check to name only that row,
// and only a read of that segment to fail.
void expect_bit_flip_named(StorageRefusal& t, const char* sql, int row, const std::vector<std::string>& words) {
  const Segments segments = random_segments(300, 31);
  const std::string blob = stored_blob(t.path_, sql);
  ASSERT_GT(blob.size(), 48u);
  const size_t at = unique_stretch(t.bytes_, blob);
  ASSERT_NE(at, std::string::npos) << "no stretch of the BLOB occurs once in the file";
  const std::string path =
      t.variant("bitflip" + std::to_string(row) + ".segmap", [&](std::string& b) { b[at + 40] ^= 0x04; });
  std::vector<std::string> expected = words;
  expected.push_back("segment row " + std::to_string(row));
  expect_storage_error([&] { MapReader::open(path).load_segments(); }, path, expected);
  const std::vector<std::string> problems = MapReader::open(path).check_integrity();
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("segment row " + std::to_string(row)), std::string::npos) << problems[0];
  const MapReader reader = MapReader::open(path);
  EXPECT_NO_THROW(reader.segments_near(segments[5].centroid, 0.f));
  EXPECT_THROW(reader.segments_near(segments[row - 1].centroid, 0.f), StorageError);
}

TEST_F(StorageRefusal, CorruptedDescriptors) {
  expect_bit_flip_named(*this, "SELECT esf FROM segments WHERE row = 101", 101, {"corrupted", "checksum mismatch"});
}

// Schema 2 keeps points in their own rows with their own checksum: a flipped bit there is
// named as such.
TEST_F(StorageRefusal, CorruptedPointRow) {
  expect_bit_flip_named(*this, "SELECT points FROM segment_points WHERE row = 201", 201,
                        {"corrupted", "points checksum mismatch"});
}

TEST_F(StorageRefusal, MissingPointRowIsNamed) {
  const std::string path = variant("nopoints.segmap", [](std::string&) {});
  run_sql(path, "DELETE FROM segment_points WHERE row = 7");
  expect_storage_error([&] { MapReader::open(path).load_segments(); }, path, {"corrupted", "segment row 7"});
  const std::vector<std::string> problems = MapReader::open(path).check_integrity();
  ASSERT_FALSE(problems.empty());
  EXPECT_NE(problems[0].find("point rows"), std::string::npos) << problems[0];
}

// SQLite hands a zero-length BLOB over as a null pointer; checksumming one added 8 to null
// (undefined behaviour that UBSan reported under fuzz_map). Now it is a checksum mismatch like
// any other damage, named by row.
TEST_F(StorageRefusal, EmptyPointBlobIsAChecksumMismatch) {
  const std::string path = variant("emptypoints.segmap", [](std::string&) {});
  run_sql(path, "UPDATE segment_points SET points = x'' WHERE row = 9");
  expect_storage_error([&] { MapReader::open(path).load_segments(); }, path, {"corrupted", "segment row 9"});
  const std::vector<std::string> problems = MapReader::open(path).check_integrity();
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("segment row 9"), std::string::npos) << problems[0];
}

// map_info's counts size allocations before any row is read: a negative one reached
// vector::reserve as 2^64 - 103 (found by fuzz_map), a huge one would ask for terabytes. Both are
// named as damage.
TEST_F(StorageRefusal, ImpossibleSegmentCountIsNamed) {
  for (const char* count : {"-103", "4000000000000"}) {
    const std::string path = variant(std::string("count") + count + ".segmap", [](std::string&) {});
    run_sql(path, (std::string("UPDATE map_info SET segment_count = ") + count).c_str());
    expect_storage_error([&] { MapReader::open(path).load_segments_without_points(); }, path,
                         {"corrupted", std::string("records ") + count + " segments"});
  }
}

TEST_F(StorageRefusal, CorruptedClassifier) {
  const std::string packed = stored_blob(path_, "SELECT bytes FROM classifier");
  ASSERT_GT(packed.size(), 8u);
  const size_t at = bytes_.find(packed);
  ASSERT_NE(at, std::string::npos);
  for (const size_t offset : {size_t{5}, packed.size() - 2}) {  // frame header, then content
    const std::string path =
        variant("classifier" + std::to_string(offset) + ".segmap", [&](std::string& b) { b[at + offset] ^= 0x08; });
    expect_storage_error([&] { MapReader::open(path).classifier(); }, path, {"corrupted", "classifier"});
  }
}

TEST_F(StorageRefusal, MissingFileOrFolder) {
  const std::string missing = dir_.file("nope.segmap");
  expect_storage_error([&] { MapReader::open(missing); }, missing, {"does not exist"});
  expect_storage_error([&] { MapReader::open(dir_.path()); }, dir_.path(), {"is a directory"});
  const std::string no_folder = dir_.file("no/such/folder/map.segmap");
  expect_storage_error([&] { MapWriter::create(no_folder, test_metadata(), true); }, no_folder, {"does not exist"});
}

TEST_F(StorageRefusal, ExistingMapIsNotOverwrittenByDefault) {
  const std::vector<std::string> before = dir_.entries();
  expect_storage_error([&] { MapWriter::create(path_, test_metadata("B"), false); }, path_,
                       {"already exists", "overwrite=true"});
  EXPECT_EQ(dir_.entries(), before);  // refused before any work: no temporary file either
  EXPECT_EQ(read_bytes(path_), bytes_);

  write_test_map(path_, random_segments(3, 1), "B", /*overwrite=*/true);
  EXPECT_EQ(MapReader::open(path_).metadata().name, "B");
  EXPECT_EQ(MapReader::open(path_).stats().segments, 3u);
  EXPECT_EQ(dir_.entries(), before);
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
