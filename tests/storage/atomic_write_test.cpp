// A map is all or nothing: a writer that never commits (destroyed, the process exiting or
// killed) leaves no file at the target path and the previous map there intact.
#include "storage_test_util.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

namespace segmatch {
namespace storage {
namespace test {
namespace {

enum class Ending { kExit, kKill };

// Forks a child that starts writing `path` (overwrite=true) and then either _exit()s without
// running destructors or is SIGKILLed by the parent while still adding segments.
void write_in_child_and_die(const std::string& path, Ending ending) {
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(ready[0]);
    try {
      MapWriter writer = MapWriter::create(path, test_metadata("child"), true);
      const Segments batch = random_segments(50, 2);
      writer.add_segments(batch, {});
      if (::write(ready[1], "r", 1) != 1) ::_exit(3);
      if (ending == Ending::kExit) ::_exit(0);
      for (;;) writer.add_segments(batch, {});  // until killed
    } catch (...) {
      ::_exit(2);
    }
  }
  ::close(ready[1]);
  char byte = 0;
  ASSERT_EQ(::read(ready[0], &byte, 1), 1) << "child failed before writing";
  ::close(ready[0]);
  if (ending == Ending::kKill) ::kill(child, SIGKILL);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  if (ending == Ending::kKill) {
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  } else {
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  }
}

bool exists(const std::string& path) { return std::filesystem::exists(path); }

TEST(StorageAtomicWrite, DestroyedWriterLeavesNothing) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  {
    MapWriter writer = MapWriter::create(path, test_metadata(), false);
    writer.add_segments(random_segments(100, 1), {});
    writer.set_trajectory(random_trajectory(5, 1));
    EXPECT_TRUE(exists(writer.temporary_path()));
    EXPECT_EQ(writer.temporary_path().rfind(path + ".tmp-" + std::to_string(::getpid()) + "-", 0), 0u);
    EXPECT_FALSE(exists(path));
  }
  EXPECT_TRUE(dir.entries().empty());
}

TEST(StorageAtomicWrite, DestroyedWriterKeepsTheOldMap) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(40, 3), "old");
  const std::string old_bytes = read_bytes(path);
  {
    MapWriter writer = MapWriter::create(path, test_metadata("new"), true);
    writer.add_segments(random_segments(100, 1), {});
  }
  EXPECT_EQ(read_bytes(path), old_bytes);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"map.segmap"});
  EXPECT_EQ(MapReader::open(path).metadata().name, "old");
}

TEST(StorageAtomicWrite, ProcessExitingBeforeCommit) {
  TempDir dir;
  const std::string fresh = dir.file("fresh.segmap");
  write_in_child_and_die(fresh, Ending::kExit);
  EXPECT_FALSE(exists(fresh));

  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(40, 3), "old");
  const std::string old_bytes = read_bytes(path);
  write_in_child_and_die(path, Ending::kExit);
  EXPECT_EQ(read_bytes(path), old_bytes);
  EXPECT_EQ(MapReader::open(path).metadata().name, "old");
  EXPECT_TRUE(MapReader::open(path).check_integrity().empty());
}

TEST(StorageAtomicWrite, ProcessKilledWhileWriting) {
  TempDir dir;
  const std::string fresh = dir.file("fresh.segmap");
  write_in_child_and_die(fresh, Ending::kKill);
  EXPECT_FALSE(exists(fresh));

  const std::string path = dir.file("map.segmap");
  write_test_map(path, random_segments(40, 3), "old");
  const std::string old_bytes = read_bytes(path);
  write_in_child_and_die(path, Ending::kKill);
  EXPECT_EQ(read_bytes(path), old_bytes);
  EXPECT_EQ(MapReader::open(path).metadata().name, "old");
  // What a killed writer leaves is only its own temporary file, never a map-looking name.
  for (const std::string& name : dir.entries()) {
    EXPECT_TRUE(name == "map.segmap" || name.find(".tmp-") != std::string::npos) << name;
  }
}

TEST(StorageAtomicWrite, MapAppearingDuringTheWriteIsNotReplaced) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  MapWriter writer = MapWriter::create(path, test_metadata("late"), false);
  writer.add_segments(random_segments(10, 1), {});
  write_test_map(path, random_segments(5, 9), "first");  // someone else was quicker
  expect_storage_error([&] { writer.commit(); }, path, {"already exists"});
  EXPECT_EQ(MapReader::open(path).metadata().name, "first");
}

TEST(StorageAtomicWrite, CommitPublishesAndCleansUp) {
  TempDir dir;
  const std::string path = dir.file("map.segmap");
  MapWriter writer = MapWriter::create(path, test_metadata(), false);
  writer.add_segments(random_segments(10, 1), {});
  writer.commit();
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"map.segmap"});
  EXPECT_THROW(writer.add_segments(random_segments(1, 1), {}), std::logic_error);
  MapWriter moved = std::move(writer);  // moving a finished writer is harmless
  EXPECT_EQ(MapReader::open(path).stats().segments, 10u);
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
