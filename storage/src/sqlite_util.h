// Thin RAII layer over the SQLite C API. Every statement is prepared; values are always bound,
// never spliced into SQL text. Failures throw StorageError naming the map file.
#pragma once

#include <segmatch/storage/map_types.h>

#include "bytes.h"

#include <sqlite3.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

namespace segmatch {
namespace storage {
namespace detail {

// "<path>: <problem>" as a StorageError.
[[noreturn]] void fail(const std::string& path, const std::string& problem);
// Turns an SQLite result code (and the connection's message) into a StorageError whose text
// says what it means for a map file (corrupted, not a database, disk full, read-only...).
[[noreturn]] void fail_sqlite(sqlite3* db, int rc, const std::string& path, const std::string& doing);
std::string describe(sqlite3* db, int rc, const std::string& doing);

struct ConnectionCloser {
  void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
using Connection = std::unique_ptr<sqlite3, ConnectionCloser>;

// flags: SQLITE_OPEN_READONLY or SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE.
Connection open_connection(const std::string& path, int flags);
// Runs fixed SQL (schema, BEGIN/COMMIT, constant PRAGMAs); never pass text holding values.
void exec(sqlite3* db, const char* sql, const std::string& path);

class Statement {
 public:
  Statement(sqlite3* db, const char* sql, const std::string& path);
  ~Statement();
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  // Parameters are numbered from 1, as in SQLite.
  void bind_int(int i, int64_t value);
  void bind_double(int i, double value);
  void bind_text(int i, const std::string& value);
  void bind_blob(int i, const void* data, size_t size);  // data copied (SQLITE_TRANSIENT)
  void bind_null(int i);

  // True when a row is available, false when done.
  bool step();
  // Runs a statement that returns no rows, then resets it for the next use.
  void run();
  void reset();

  // Columns are numbered from 0.
  bool is_null(int c) const;
  int64_t column_int(int c) const;
  double column_double(int c) const;
  std::string column_text(int c) const;
  // Valid until the next step() / reset().
  BlobView column_blob(int c) const;

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  std::string path_;
};

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
