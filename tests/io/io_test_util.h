// Shared helpers for the io tests: a self-cleaning temp folder, raw file access, random
// clouds and a checker for IoError messages.
#pragma once

#include <gtest/gtest.h>
#include <segmatch/core/common/types.h>
#include <segmatch/io/error.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <random>
#include <string>
#include <vector>

namespace segmatch {
namespace io {
namespace test {

// A unique folder under the system temp dir, removed with everything in it on destruction.
class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    const auto stamp = std::to_string(rd()) + "_" + std::to_string(rd());
    path_ = std::filesystem::temp_directory_path() / ("segmatch_io_test_" + stamp);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string path() const { return path_.string(); }

 private:
  std::filesystem::path path_;
};

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  // Replace rather than truncate: ext4 flushes a file truncated to zero (auto_da_alloc),
  // which made the fuzz tests wait on the disk for every file.
  std::error_code ec;
  std::filesystem::remove(path, ec);
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << "cannot write test file " << path;
}

inline std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Appends the raw bytes of a value (little-endian host), to hand-build binary files.
template <typename T>
void append_raw(std::string* out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out->append(bytes, sizeof(T));
}

// Same, most significant byte first (for big-endian PLY).
template <typename T>
void append_raw_big_endian(std::string* out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  for (size_t i = sizeof(T); i > 0; --i) out->push_back(bytes[i - 1]);
}

inline PointCloud random_cloud(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> coord(-80.0f, 80.0f);
  std::uniform_real_distribution<float> intensity(0.0f, 1.0f);
  PointCloud cloud(n);
  for (Point& p : cloud) {
    p.x = coord(rng);
    p.y = coord(rng);
    p.z = coord(rng) / 10.0f;
    p.intensity = intensity(rng);
  }
  return cloud;
}

inline std::vector<uint32_t> random_labels(size_t n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<uint32_t> labels(n);
  for (uint32_t& l : labels) l = encode_label(static_cast<uint16_t>(rng() % 260), static_cast<uint16_t>(rng() % 50));
  return labels;
}

inline bool same_points(const PointCloud& a, const PointCloud& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Point)) == 0);
}

// Runs fn and checks that it throws IoError whose message contains every part.
template <typename Fn>
::testing::AssertionResult ThrowsIoError(Fn fn, std::initializer_list<std::string> parts) {
  try {
    fn();
  } catch (const IoError& e) {
    const std::string message = e.what();
    for (const std::string& part : parts) {
      if (message.find(part) == std::string::npos) {
        return ::testing::AssertionFailure() << "IoError message \"" << message << "\" lacks \"" << part << "\"";
      }
    }
    return ::testing::AssertionSuccess() << message;
  } catch (const std::exception& e) {
    return ::testing::AssertionFailure() << "threw a non-IoError exception: " << e.what();
  }
  return ::testing::AssertionFailure() << "did not throw";
}

// For fuzzing: the call may succeed or throw IoError, but nothing else.
template <typename Fn>
::testing::AssertionResult SucceedsOrThrowsIoError(Fn fn) {
  try {
    fn();
  } catch (const IoError&) {
  } catch (const std::exception& e) {
    return ::testing::AssertionFailure() << "threw a non-IoError exception: " << e.what();
  }
  return ::testing::AssertionSuccess();
}

}  // namespace test
}  // namespace io
}  // namespace segmatch
