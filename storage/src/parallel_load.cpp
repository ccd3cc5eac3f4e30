// MapReader::load_segments(): the rows are split into contiguous ranges, each read through
// its own connection on its own thread and decoded straight into its final slot. Decoding
// (and the page faults of a gigabyte of fresh point memory) dominate a full load, so this
// scales with the cores (target: 100k segments with points well under 2 s).
#include "reader_impl.h"
#include "segment_rows.h"

#include <sys/mman.h>

#include <cstdint>
#include <exception>
#include <thread>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

constexpr uint64_t kMinRowsPerThread = 2048;  // below this a thread costs more than it saves

struct Chunk {
  sqlite3* db = nullptr;
  int64_t first_row = 0, last_row = 0;
  uint64_t loaded = 0;
  std::exception_ptr error;
};

void load_chunk(const std::string& path, int schema_version, bool with_points, Chunk* chunk, Segments* out,
                std::vector<uint32_t>* keyframes) {
  try {
    const std::string sql =
        select_segments_sql(schema_version, "WHERE s.row BETWEEN ? AND ? ORDER BY s.row", with_points);
    Statement st(chunk->db, sql.c_str(), path);
    st.bind_int(1, chunk->first_row);
    st.bind_int(2, chunk->last_row);
    StoredRow stored;
    while (st.step()) {
      read_row(st, schema_version, &stored);
      const size_t index = static_cast<size_t>(stored.row_id - 1);  // rows are 1..N
      decode_segment(stored, path, &(*out)[index], with_points);
      if (keyframes) (*keyframes)[index] = stored.row.keyframe;
      ++chunk->loaded;
    }
  } catch (...) {
    chunk->error = std::current_exception();
  }
}

// A city map's segments are hundreds of megabytes (an ESF alone is 2.5 KB) that the load touches
// for the first time: asking for transparent huge pages before that (where the kernel leaves
// it to madvise) takes one fault per 2 MB instead of one per 4 KB page, which is most of the
// load's time on a virtual machine (docs/measurements.md, "Map size and storage"). Only advice: ignored where refused.
void prefer_huge_pages(void* data, size_t bytes) {
  const uintptr_t huge = uintptr_t{2} << 20;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + huge - 1) & ~(huge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + bytes) & ~(huge - 1);
  if (end > begin) ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

int64_t query_int(sqlite3* db, const char* sql, const std::string& path) {
  Statement st(db, sql, path);
  return st.step() ? st.column_int(0) : 0;
}

// The writer numbers rows 1..N; anything else is not a map it wrote.
void check_row_span(const MapReader::Impl& impl) {
  const int64_t n = static_cast<int64_t>(impl.segment_count);
  // Separate queries: SQLite answers a lone min() / max() of the rowid from the b-tree ends.
  const int64_t first = query_int(impl.db.get(), "SELECT min(row) FROM segments", impl.path);
  const int64_t last = query_int(impl.db.get(), "SELECT max(row) FROM segments", impl.path);
  if ((n == 0 && last != 0) || (n > 0 && (first != 1 || last != n))) {
    fail(impl.path, "the map file is corrupted: map_info records " + std::to_string(n) + " segments, the rows span " +
                        std::to_string(first) + ".." + std::to_string(last));
  }
}

}  // namespace

Segments load_all_segments(const MapReader::Impl& impl, std::vector<uint32_t>* keyframes, bool with_points) {
  check_row_span(impl);
  const uint64_t n = impl.segment_count;
  Segments out;
  out.reserve(n);
  prefer_huge_pages(out.data(), n * sizeof(Segment));
  out.resize(n);
  if (keyframes) keyframes->assign(n, kNoKeyframe);
  const uint64_t threads = std::max<uint64_t>(1, std::min<uint64_t>(1 + impl.loaders.size(), n / kMinRowsPerThread));
  std::vector<Chunk> chunks(threads);
  for (uint64_t c = 0; c < threads; ++c) {
    chunks[c].db = c == 0 ? impl.db.get() : impl.loaders[c - 1].get();
    chunks[c].first_row = static_cast<int64_t>(n * c / threads + 1);
    chunks[c].last_row = static_cast<int64_t>(n * (c + 1) / threads);
  }
  std::vector<std::thread> workers;
  for (uint64_t c = 1; c < threads; ++c) {
    workers.emplace_back(load_chunk, std::cref(impl.path), impl.schema_version, with_points, &chunks[c], &out,
                         keyframes);
  }
  load_chunk(impl.path, impl.schema_version, with_points, &chunks[0], &out, keyframes);
  for (std::thread& w : workers) w.join();
  uint64_t loaded = 0;
  for (const Chunk& chunk : chunks) {
    if (chunk.error) std::rethrow_exception(chunk.error);
    loaded += chunk.loaded;
  }
  if (loaded != n) {
    fail(impl.path, "the map file is corrupted: map_info records " + std::to_string(n) + " segments, the file holds " +
                        std::to_string(loaded));
  }
  return out;
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
