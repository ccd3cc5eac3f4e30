// File-system steps of an atomic map write: checking the target, fsync, the final rename.
#pragma once

#include <string>

namespace segmatch {
namespace storage {
namespace detail {

// The folder holding `path` ("." for a bare file name).
std::string parent_folder(const std::string& path);
// Refuses, before any work, a target whose folder is missing, that is a directory, or that
// exists while overwrite is false.
void check_target(const std::string& path, bool overwrite);
// fsync of a file or (is_folder) of a folder, so a rename into it survives a power cut.
void fsync_path(const std::string& path, bool is_folder);
// Atomically gives `from` the name `to`. Without overwrite, a file that appeared at `to`
// since check_target() is not replaced (link() fails on an existing name).
void move_into_place(const std::string& from, const std::string& to, bool overwrite);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
