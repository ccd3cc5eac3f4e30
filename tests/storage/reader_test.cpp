// Readers open the map read-only and coexist: several readers, several threads, and a writer
// replacing the map under an open reader.
#include "storage_test_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <thread>

namespace segmatch {
namespace storage {
namespace test {
namespace {

// Access mode of every descriptor this process holds on `path` (from /proc/self/fdinfo).
std::vector<int> access_modes_of(const std::string& path) {
  std::vector<int> modes;
  const auto target = std::filesystem::canonical(path);
  for (const auto& fd : std::filesystem::directory_iterator("/proc/self/fd")) {
    std::error_code ec;
    const auto link = std::filesystem::read_symlink(fd.path(), ec);
    if (ec || link != target) continue;
    std::ifstream info("/proc/self/fdinfo/" + fd.path().filename().string());
    std::string key, value;
    while (info >> key >> value) {
      if (key == "flags:") modes.push_back(std::stoi(value, nullptr, 8) & O_ACCMODE);
    }
  }
  return modes;
}

struct Snapshot {
  std::string bytes;
  struct timespec mtime;
  std::vector<std::string> entries;
};

Snapshot snapshot(const TempDir& dir, const std::string& path) {
  struct stat st;
  ::stat(path.c_str(), &st);
  return {read_bytes(path), st.st_mtim, dir.entries()};
}

TEST(StorageReader, OpensReadOnlyAndChangesNothing) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(200, 4));
  const Snapshot before = snapshot(dir, path);
  // No write permission needed, on the file or on its folder (no journal, no -shm).
  std::filesystem::permissions(path, std::filesystem::perms::owner_read);
  std::filesystem::permissions(dir.path(), std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
  {
    const MapReader reader = MapReader::open(path);
    reader.load_segments();
    reader.segments_near({0.f, 0.f, 0.f}, 50.f);
    reader.trajectory();
    reader.classifier();
    EXPECT_TRUE(reader.check_integrity().empty());
    const std::vector<int> modes = access_modes_of(path);
    ASSERT_FALSE(modes.empty());
    for (int mode : modes) EXPECT_EQ(mode, O_RDONLY) << "map descriptor not read-only";
  }
  std::filesystem::permissions(dir.path(), std::filesystem::perms::owner_all);
  const Snapshot after = snapshot(dir, path);
  EXPECT_TRUE(after.bytes == before.bytes);
  EXPECT_EQ(after.mtime.tv_sec, before.mtime.tv_sec);
  EXPECT_EQ(after.mtime.tv_nsec, before.mtime.tv_nsec);
  EXPECT_EQ(after.entries, before.entries);
}

TEST(StorageReader, TwoReadersAtOnce) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  const Segments segments = random_segments(500, 6);
  write_test_map(path, segments);
  const MapReader a = MapReader::open(path);
  const MapReader b = MapReader::open(path);
  const Segments from_a = a.load_segments();
  const Segments near_b = b.segments_near(segments[3].centroid, 80.f);
  const Segments from_b = b.load_segments();
  const Segments near_a = a.segments_near(segments[3].centroid, 80.f);
  ASSERT_EQ(from_a.size(), segments.size());
  ASSERT_EQ(from_b.size(), segments.size());
  ASSERT_EQ(near_a.size(), near_b.size());
  for (size_t i = 0; i < near_a.size(); ++i) EXPECT_EQ(near_a[i].id, near_b[i].id);
}

TEST(StorageReader, ThreadsWithOwnAndSharedReaders) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  const Segments segments = random_segments(400, 8);
  write_test_map(path, segments);
  const MapReader shared = MapReader::open(path);
  std::vector<size_t> loaded(6, 0);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < loaded.size(); ++t) {
    threads.emplace_back([&, t] {
      for (int round = 0; round < 3; ++round) {
        if (t % 2 == 0) {
          loaded[t] += MapReader::open(path).load_segments().size();
        } else {
          loaded[t] += shared.load_segments().size();
          loaded[t] += shared.segments_near(segments[t].centroid, 1e-3f).size() - 1;
        }
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (size_t n : loaded) EXPECT_EQ(n, 3 * segments.size());
}

TEST(StorageReader, OpenReaderKeepsTheMapItOpened) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(50, 1), "old");
  const MapReader old_reader = MapReader::open(path);
  write_test_map(path, random_segments(7, 2), "new", /*overwrite=*/true);
  EXPECT_EQ(old_reader.load_segments().size(), 50u);
  EXPECT_EQ(old_reader.metadata().name, "old");
  EXPECT_EQ(MapReader::open(path).load_segments().size(), 7u);
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
