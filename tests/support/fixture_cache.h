// Expensive test fixtures built once and shared by every test process that needs them (CTest
// runs each entry in its own process, two at a time): a folder under the build folder's
// tests/fixtures/, built under an exclusive lock so that parallel processes wait for one build
// instead of each making its own, and rebuilt when one of the programs that made it is newer
// than its stamp (a rebuilt tool or test executable makes it stale).
#pragma once

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace segmatch::test {

// The build folder's tests/fixtures/ (SEGMATCH_BIN_DIR is <build>/bin), or $SEGMATCH_FIXTURE_DIR.
inline std::filesystem::path fixture_root() {
  if (const char* dir = std::getenv("SEGMATCH_FIXTURE_DIR")) return dir;
  return std::filesystem::path(SEGMATCH_BIN_DIR).parent_path() / "tests" / "fixtures";
}

// An exclusive flock on <folder>.lock for the lifetime of the object; released by the kernel
// if the process dies, so a crashed build never leaves the others waiting.
class FixtureLock {
 public:
  explicit FixtureLock(const std::filesystem::path& folder) {
    std::filesystem::create_directories(folder.parent_path());
    const std::string path = folder.string() + ".lock";
    fd_ = ::open(path.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
    if (fd_ < 0 || ::flock(fd_, LOCK_EX) != 0) throw std::runtime_error("cannot lock " + path);
  }
  ~FixtureLock() {
    ::flock(fd_, LOCK_UN);
    ::close(fd_);
  }
  FixtureLock(const FixtureLock&) = delete;
  FixtureLock& operator=(const FixtureLock&) = delete;

 private:
  int fd_ = -1;
};

// True when `stamp` exists and no file of `inputs` was written after it.
inline bool newer_than_all(const std::filesystem::path& stamp, const std::vector<std::filesystem::path>& inputs) {
  std::error_code ec;
  const auto stamped = std::filesystem::last_write_time(stamp, ec);
  if (ec) return false;
  for (const auto& input : inputs)
    if (std::filesystem::last_write_time(input) > stamped) return false;
  return true;
}

// The folder of fixture `name`, built by build(folder) unless a finished build newer than every
// file of `inputs` is there. A build that throws leaves no stamp, so the next process retries.
inline std::filesystem::path cached_fixture(const std::string& name, const std::vector<std::filesystem::path>& inputs,
                                            const std::function<void(const std::filesystem::path&)>& build) {
  const std::filesystem::path folder = fixture_root() / name, stamp = folder / ".complete";
  const FixtureLock lock(folder);
  if (!newer_than_all(stamp, inputs)) {
    std::filesystem::remove_all(folder);
    std::filesystem::create_directories(folder);
    build(folder);
    std::ofstream(stamp) << name << "\n";
    if (!std::filesystem::exists(stamp)) throw std::runtime_error("cannot write " + stamp.string());
  }
  return folder;
}

// This test executable, as an input of the fixtures it builds in process.
inline std::filesystem::path this_executable() { return std::filesystem::read_symlink("/proc/self/exe"); }

}  // namespace segmatch::test
