// Shared by the file-format fuzz targets: the input is written to a file (the readers' entry
// points take paths, as users call them) in a per-process folder under /dev/shm when it exists
// (memory, not disk), and the module's own error type is the only exception allowed.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <string>

namespace segmatch {
namespace fuzz {

// A folder of this process's own, removed when the process exits normally.
struct Scratch {
  std::string folder;
  Scratch() {
    const bool shm = std::filesystem::exists("/dev/shm");
    folder = (shm ? std::string("/dev/shm") : std::filesystem::temp_directory_path().string()) + "/segmatch_fuzz_" +
             std::to_string(::getpid());
    std::filesystem::create_directories(folder);
  }
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(folder, ec);
  }
};

inline std::string scratch_file(const char* name) {
  static const Scratch scratch;
  return scratch.folder + "/" + name;
}

inline std::string write_input(const char* name, const uint8_t* data, size_t size) {
  const std::string path = scratch_file(name);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) std::abort();
  return path;
}

// Runs `read`; the error type E is an accepted answer to bad input, anything else a finding.
template <typename E, typename F>
void expect_only(F&& read) {
  try {
    read();
  } catch (const E&) {
  } catch (const std::exception& e) {
    std::fprintf(stderr, "unexpected exception: %s\n", e.what());
    std::abort();
  }
}

}  // namespace fuzz
}  // namespace segmatch
