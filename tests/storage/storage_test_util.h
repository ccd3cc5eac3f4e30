// Shared helpers for the storage tests: a self-cleaning temp folder, synthetic maps, raw file
// access and a checker for StorageError messages.
#pragma once

#include <gtest/gtest.h>
#include <segmatch/core/description/esf_quantization.h>
#include <segmatch/storage/map_reader.h>
#include <segmatch/storage/map_writer.h>
#include <sqlite3.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {
namespace test {

class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = std::filesystem::temp_directory_path() /
            ("segmatch_storage_test_" + std::to_string(rd()) + "_" + std::to_string(rd()));
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::permissions(path_, std::filesystem::perms::owner_all, std::filesystem::perm_options::add, ec);
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::string file(const std::string& name) const { return (path_ / name).string(); }
  std::string path() const { return path_.string(); }
  // Names of everything in the folder, sorted.
  std::vector<std::string> entries() const {
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(path_)) {
      names.push_back(e.path().filename().string());
    }
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  std::filesystem::path path_;
};

inline std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The stored bytes of one BLOB (first column of the first row `sql` selects), read with
// SQLite itself: schema 2 packs descriptors and points, so the tests find a row's bytes in the
// file by what is stored rather than by what was written.
inline std::string stored_blob(const std::string& path, const char* sql) {
  sqlite3* db = nullptr;
  std::string out;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db, sql, -1, &st, nullptr) == SQLITE_OK && sqlite3_step(st) == SQLITE_ROW)
      out.assign(static_cast<const char*>(sqlite3_column_blob(st, 0)), sqlite3_column_bytes(st, 0));
    sqlite3_finalize(st);
  }
  sqlite3_close(db);
  return out;
}

inline void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << "cannot write " << path;
}

// A random segment around `center`: `n` points within `extent` metres, intensities in [0, 1],
// random descriptors (left out for every 7th / 5th id to cover has_eigen / has_esf = false).
inline Segment random_segment(std::mt19937& rng, uint64_t id, const Eigen::Vector3f& center, size_t n,
                              float extent = 3.f) {
  std::uniform_real_distribution<float> offset(-extent, extent), unit(0.f, 1.f);
  Segment s;
  s.id = id;
  s.label = static_cast<uint32_t>(rng());
  for (size_t i = 0; i < n; ++i) {
    s.points.push_back(
        {center.x() + offset(rng), center.y() + offset(rng), center.z() + offset(rng) * 0.5f, unit(rng)});
  }
  Eigen::Vector3f sum = Eigen::Vector3f::Zero();
  for (const Point& p : s.points) sum += p.xyz();
  s.centroid = n ? Eigen::Vector3f(sum / float(n)) : center;
  s.has_eigen = id % 7 != 3;
  s.has_esf = id % 5 != 2;
  if (s.has_eigen)
    for (float& v : s.eigen) v = unit(rng);
  if (s.has_esf)
    for (float& v : s.esf) v = unit(rng) * 0.01f;
  return s;
}

// `count` segments spread over a `size` x `size` m area.
inline Segments random_segments(size_t count, uint32_t seed, float size = 500.f, size_t min_points = 20,
                                size_t max_points = 200) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> where(-size / 2, size / 2), height(0.f, 10.f);
  std::uniform_int_distribution<size_t> points(min_points, max_points);
  Segments segments;
  for (size_t i = 0; i < count; ++i) {
    const Eigen::Vector3f center(where(rng), where(rng), height(rng));
    segments.push_back(random_segment(rng, 1000 + i * 3, center, points(rng)));
  }
  return segments;
}

inline std::vector<Keyframe> random_trajectory(size_t count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> step(0.5, 2.0), angle(-3.1, 3.1);
  std::vector<Keyframe> keyframes;
  Eigen::Vector3d position(100.123456789, -20.5, 3.25);
  for (size_t i = 0; i < count; ++i) {
    Keyframe k;
    k.index = static_cast<uint32_t>(i * 2);
    k.time_s = 1.6e9 + 0.1 * double(i) + 1e-7;
    position += Eigen::Vector3d(step(rng), step(rng) * 0.3, 0.01);
    k.T_map_sensor = Pose3d::Identity();
    k.T_map_sensor.linear() =
        (Eigen::AngleAxisd(angle(rng), Eigen::Vector3d(0.1, 0.2, 1.0).normalized())).toRotationMatrix();
    k.T_map_sensor.translation() = position;
    keyframes.push_back(k);
  }
  return keyframes;
}

inline MapMetadata test_metadata(const std::string& name = "test map") {
  MapMetadata m;
  m.name = name;
  m.frame = "map";
  m.created_utc = "1999-05-01T12:34:56Z";
  m.tool_version = "segmatch 0.1.0-test";
  m.parameters_json = R"({"voxel_size_m": 0.1, "segmenter": "euclidean", "esf_bins": 640})";
  return m;
}

// Writes a committed map with segments (keyframe i % 10 * 2), a trajectory and a classifier.
inline void write_test_map(const std::string& path, const Segments& segments, const std::string& name = "test map",
                           bool overwrite = false) {
  MapWriter writer = MapWriter::create(path, test_metadata(name), overwrite);
  std::vector<uint32_t> keyframes;
  for (size_t i = 0; i < segments.size(); ++i) keyframes.push_back(uint32_t(i % 10) * 2);
  writer.add_segments(segments, keyframes);
  writer.set_trajectory(random_trajectory(10, 7));
  writer.set_classifier({"test-format", std::string("\0model\xff bytes", 13)});
  writer.commit();
}

// An ESF as a schema-3 map stores it: quantised (core/esf_quantization.h).
inline EsfDescriptor as_stored_esf(const EsfDescriptor& esf) {
  const QuantizedEsf q = quantize_esf(esf, kMapEsfMinExponent, kMapEsfMaxExponent);
  EsfDescriptor out;
  for (int i = 0; i < kEsfBins; ++i) out[i] = dequantize_esf_bin(q.mantissas[i], esf_scale(q.exponent));
  return out;
}

// Offset in `file` of a 48-byte stretch of `blob` that occurs there exactly once, npos if none:
// a BLOB longer than a page continues on overflow pages elsewhere, and rows may begin alike
// (ESF masks).
inline size_t unique_stretch(const std::string& file, const std::string& blob) {
  for (size_t from = 0; from + 48 <= blob.size(); from += 8) {
    const std::string stretch = blob.substr(from, 48);
    const size_t first = file.find(stretch);
    if (first != std::string::npos && file.rfind(stretch) == first) return first;
  }
  return std::string::npos;
}

inline std::string lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

// Runs `fn`, expects a StorageError whose message names `path` and contains every word.
inline void expect_storage_error(const std::function<void()>& fn, const std::string& path,
                                 const std::vector<std::string>& words) {
  try {
    fn();
    ADD_FAILURE() << "no StorageError for " << path;
  } catch (const StorageError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path), std::string::npos) << message;
    for (const std::string& word : words) {
      EXPECT_NE(lower(message).find(lower(word)), std::string::npos) << "'" << word << "' missing from: " << message;
    }
  }
}

}  // namespace test
}  // namespace storage
}  // namespace segmatch
