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

// Prepared statements of one read that queries repeat (a segment's points, a surface tile):
// preparing costs more than the read itself, so they are kept for reuse, and new ones are spread
// over the reader's connections so that threads reading at once share the connections' locks.
class StatementPool {
 public:
  explicit StatementPool(const char* sql) : sql_(sql) {}
  // An idle statement, or a new one on the next connection in turn.
  std::unique_ptr<detail::Statement> take(const MapReader::Impl& impl);
  // Back for reuse after a read that succeeded (a read that threw lets its statement go).
  void give_back(std::unique_ptr<detail::Statement> st);

 private:
  const char* sql_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<detail::Statement>> idle_;
  size_t made_ = 0;
};

struct MapReader::Impl {
  std::string path;
  detail::Connection db;  // read-only, serialised (SQLITE_OPEN_FULLMUTEX)
  // More connections to the same file (same inode), one per extra loader thread.
  std::vector<detail::Connection> loaders;
  MapMetadata metadata;
  int schema_version = 0;
  // Row counts recorded by the writer at commit.
  uint64_t segment_count = 0, point_count = 0, keyframe_count = 0;
  std::optional<SurfaceLayer> surfaces;  // schema 4 with a layer
  // Reads of read_points() and surface_tile(). Declared after the connections: finalized before
  // they close.
  mutable StatementPool point_reads, tile_reads;
  Impl();
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
