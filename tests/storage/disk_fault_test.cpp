// Disk faults during a map build: a write that runs out of space (here a file-size limit, which
// the kernel enforces like a full disk: EFBIG) ends with an error naming the cause, leaves no map
// file and no temporary file behind, and keeps the map that was there before intact.
#include "storage_test_util.h"

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstring>

namespace segmatch {
namespace storage {
namespace test {
namespace {

// Runs a map build of `segments` segments to `path` in a child whose files may not grow beyond
// `limit_bytes`; returns the StorageError message it got ("" if the build succeeded).
std::string build_with_file_size_limit(const std::string& path, size_t segments, rlim_t limit_bytes) {
  int pipe_fds[2];
  if (::pipe(pipe_fds) != 0) return "pipe failed";
  const pid_t child = ::fork();
  if (child == 0) {
    ::close(pipe_fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);  // a write past the limit then fails with EFBIG instead of killing
    const rlimit limit{limit_bytes, limit_bytes};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    std::string message;
    try {
      MapWriter writer = MapWriter::create(path, test_metadata("too big"), true);
      writer.add_segments(random_segments(segments, 5), {});
      writer.commit();
    } catch (const StorageError& e) {
      message = e.what();
    } catch (const std::exception& e) {
      message = std::string("not a StorageError: ") + e.what();
    }
    if (!message.empty() && ::write(pipe_fds[1], message.data(), message.size()) < 0) ::_exit(3);
    ::_exit(0);
  }
  ::close(pipe_fds[1]);
  std::string message;
  char buffer[512];
  for (ssize_t n; (n = ::read(pipe_fds[0], buffer, sizeof(buffer))) > 0;) message.append(buffer, size_t(n));
  ::close(pipe_fds[0]);
  int status = 0;
  ::waitpid(child, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return "the child died: status " + std::to_string(status);
  return message;
}

TEST(StorageDiskFault, BuildThatRunsOutOfSpaceIsNamedAndLeavesTheOldMap) {
  TempDir dir;
  const std::string path = dir.file("city.segmap");
  const Segments before = random_segments(20, 3);
  write_test_map(path, before);
  const std::string old_bytes = read_bytes(path);
  const std::vector<std::string> entries = dir.entries();

  // Far more than 1 MB of segments against a 1 MB limit on every file the child writes.
  const std::string message = build_with_file_size_limit(path, 3000, 1u << 20);
  ASSERT_FALSE(message.empty()) << "the build did not fail";
  EXPECT_EQ(message.find("not a StorageError"), std::string::npos) << message;
  EXPECT_NE(message.find(path), std::string::npos) << message;  // names the map it was building
  EXPECT_NE(message.find("disk full, file-size limit or failing disk"), std::string::npos) << message;
  EXPECT_EQ(dir.entries(), entries) << "no new file and no temporary file left";
  EXPECT_EQ(read_bytes(path), old_bytes) << "the previous map is intact";
  EXPECT_EQ(MapReader::open(path).load_segments().size(), before.size());
}

TEST(StorageDiskFault, NewMapThatRunsOutOfSpaceLeavesNothing) {
  TempDir dir;
  const std::string path = dir.file("new.segmap");
  const std::string message = build_with_file_size_limit(path, 3000, 1u << 20);
  ASSERT_FALSE(message.empty()) << "the build did not fail";
  EXPECT_NE(message.find(path), std::string::npos) << message;
  EXPECT_TRUE(dir.entries().empty()) << "nothing left in the folder";
}

}  // namespace
}  // namespace test
}  // namespace storage
}  // namespace segmatch
