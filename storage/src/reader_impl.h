// MapReader's state, shared by map_reader.cpp and integrity.cpp.
#pragma once

#include <segmatch/storage/map_reader.h>

#include "sqlite_util.h"

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

namespace segmatch {
namespace storage {

struct MapReader::Impl {
  std::string path;
  detail::Connection db;  // read-only, serialised (SQLITE_OPEN_FULLMUTEX)
  // More connections to the same file (same inode), one per extra loader thread.
  std::vector<detail::Connection> loaders;
  MapMetadata metadata;
  int schema_version = 0;
  // Row counts recorded by the writer at commit.
  uint64_t segment_count = 0, point_count = 0, keyframe_count = 0;
  // Prepared point reads (read_points), kept for reuse: preparing the statement costs more than
  // reading a segment's points. Declared after the connections: finalized before they close.
  mutable std::mutex point_reads_mutex;
  mutable std::vector<std::unique_ptr<detail::Statement>> idle_point_reads;
  mutable size_t point_reads_made = 0;  // spreads new statements over db and loaders
};

namespace detail {
std::vector<std::string> check_integrity(const MapReader::Impl& impl);
// All segments, decoded in parallel over impl.db and impl.loaders; without their points when
// with_points is false.
Segments load_all_segments(const MapReader::Impl& impl, std::vector<uint32_t>* keyframes, bool with_points);
// The classifier row, checksum verified (StorageError when it does not match).
std::optional<ClassifierBlob> read_classifier(const MapReader::Impl& impl);
}  // namespace detail

}  // namespace storage
}  // namespace segmatch
