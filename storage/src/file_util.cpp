#include "file_util.h"

#include "sqlite_util.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

std::string error_text() { return std::strerror(errno); }

const char* const kExists = "a map already exists at this path; pass overwrite=true to replace it";

}  // namespace

std::string parent_folder(const std::string& path) {
  const std::string parent = std::filesystem::path(path).parent_path().string();
  return parent.empty() ? "." : parent;
}

void check_target(const std::string& path, bool overwrite) {
  if (path.empty()) fail("(empty path)", "no map path given");
  struct stat st;
  const std::string folder = parent_folder(path);
  if (::stat(folder.c_str(), &st) != 0 || !S_ISDIR(st.st_mode)) {
    fail(path, "the folder " + folder + " does not exist");
  }
  if (::lstat(path.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) fail(path, "is a directory, cannot write a map there");
    if (!overwrite) fail(path, kExists);
  }
}

void fsync_path(const std::string& path, bool is_folder) {
  const int fd = ::open(path.c_str(), is_folder ? O_RDONLY | O_DIRECTORY : O_RDWR);
  if (fd < 0) fail(path, "cannot open for fsync: " + error_text());
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  // Some file systems refuse fsync on folders; the data itself is already synced then.
  if (rc != 0 && !(is_folder && (err == EINVAL || err == EBADF))) {
    fail(path, std::string("fsync failed: ") + std::strerror(err));
  }
}

void move_into_place(const std::string& from, const std::string& to, bool overwrite) {
  if (overwrite) {
    if (::rename(from.c_str(), to.c_str()) != 0) fail(to, "cannot rename the map into place: " + error_text());
    return;
  }
  if (::link(from.c_str(), to.c_str()) == 0) {
    ::unlink(from.c_str());
    return;
  }
  if (errno == EEXIST) fail(to, kExists);
  // File systems without hard links: a check and a rename (a small race, documented above).
  struct stat st;
  if (::lstat(to.c_str(), &st) == 0) fail(to, kExists);
  if (::rename(from.c_str(), to.c_str()) != 0) fail(to, "cannot rename the map into place: " + error_text());
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
