#include "sqlite_util.h"

namespace segmatch {
namespace storage {
namespace detail {

void fail(const std::string& path, const std::string& problem) { throw StorageError(path + ": " + problem); }

namespace {

// What a result code means for someone holding a map file; SQLite's own text follows it.
std::string meaning(int rc) {
  // A failed write is a full disk, a file-size limit or a failing disk (SQLite reports ENOSPC as
  // SQLITE_FULL, EFBIG and the rest as these).
  if (rc == SQLITE_IOERR_WRITE || rc == SQLITE_IOERR_FSYNC || rc == SQLITE_IOERR_TRUNCATE)
    return "cannot write the file (disk full, file-size limit or failing disk)";
  switch (rc & 0xFF) {
    case SQLITE_CORRUPT: return "the map file is corrupted";
    case SQLITE_NOTADB: return "not an SQLite database (or its header is corrupted)";
    case SQLITE_FULL: return "disk full";
    case SQLITE_READONLY: return "file or folder is read-only";
    case SQLITE_CANTOPEN: return "cannot open the file";
    case SQLITE_IOERR: return "I/O error (truncated file or failing disk)";
    case SQLITE_PERM: return "permission denied";
    case SQLITE_NOMEM: return "out of memory";
    case SQLITE_CONSTRAINT: return "invalid data";
    case SQLITE_BUSY:
    case SQLITE_LOCKED: return "the file is locked by another process";
    default: return "SQLite error";
  }
}

}  // namespace

std::string describe(sqlite3* db, int rc, const std::string& doing) {
  const char* detail = db ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  // The extended code tells a failed write from a failed read (result codes are primary).
  const int code = db && (sqlite3_errcode(db) & 0xFF) == (rc & 0xFF) ? sqlite3_extended_errcode(db) : rc;
  return meaning(code) + " (while " + doing + "; SQLite: " + detail + ")";
}

void fail_sqlite(sqlite3* db, int rc, const std::string& path, const std::string& doing) {
  fail(path, describe(db, rc, doing));
}

Connection open_connection(const std::string& path, int flags) {
  sqlite3* raw = nullptr;
  // FULLMUTEX: a MapReader may be used from several threads (see map_reader.h).
  const int rc = sqlite3_open_v2(path.c_str(), &raw, flags | SQLITE_OPEN_FULLMUTEX, nullptr);
  Connection db(raw);
  if (rc != SQLITE_OK) fail_sqlite(db.get(), rc, path, "opening");
  sqlite3_extended_result_codes(db.get(), 1);
  return db;
}

void exec(sqlite3* db, const char* sql, const std::string& path) {
  char* message = nullptr;
  const int rc = sqlite3_exec(db, sql, nullptr, nullptr, &message);
  if (rc == SQLITE_OK) return;
  const std::string text = message ? message : sqlite3_errstr(rc);
  sqlite3_free(message);
  fail(path, meaning(rc) + " (while running \"" + std::string(sql).substr(0, 60) + "\"; SQLite: " + text + ")");
}

Statement::Statement(sqlite3* db, const char* sql, const std::string& path) : db_(db), path_(path) {
  const int rc = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  if (rc != SQLITE_OK) {
    fail_sqlite(db, rc, path, "preparing \"" + std::string(sql).substr(0, 60) + "\"");
  }
}

Statement::~Statement() { sqlite3_finalize(stmt_); }

void Statement::bind_int(int i, int64_t value) {
  const int rc = sqlite3_bind_int64(stmt_, i, value);
  if (rc != SQLITE_OK) fail_sqlite(db_, rc, path_, "binding a value");
}

void Statement::bind_double(int i, double value) {
  const int rc = sqlite3_bind_double(stmt_, i, value);
  if (rc != SQLITE_OK) fail_sqlite(db_, rc, path_, "binding a value");
}

void Statement::bind_text(int i, const std::string& value) {
  const int rc = sqlite3_bind_text64(stmt_, i, value.data(), value.size(), SQLITE_TRANSIENT, SQLITE_UTF8);
  if (rc != SQLITE_OK) fail_sqlite(db_, rc, path_, "binding a text");
}

void Statement::bind_blob(int i, const void* data, size_t size) {
  // A zero-length blob must stay a blob (not NULL): SQLite needs a non-null pointer for that.
  static const char empty = 0;
  const int rc = sqlite3_bind_blob64(stmt_, i, size ? data : &empty, size, SQLITE_TRANSIENT);
  if (rc != SQLITE_OK) fail_sqlite(db_, rc, path_, "binding a blob");
}

void Statement::bind_null(int i) {
  const int rc = sqlite3_bind_null(stmt_, i);
  if (rc != SQLITE_OK) fail_sqlite(db_, rc, path_, "binding a value");
}

bool Statement::step() {
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  const std::string problem = describe(db_, rc, "running \"" + std::string(sqlite3_sql(stmt_)).substr(0, 60) + "\"");
  // Leave the statement reusable for callers that catch and continue (check_integrity).
  sqlite3_reset(stmt_);
  fail(path_, problem);
}

void Statement::run() {
  step();
  reset();
}

void Statement::reset() {
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
}

bool Statement::is_null(int c) const { return sqlite3_column_type(stmt_, c) == SQLITE_NULL; }

int64_t Statement::column_int(int c) const { return sqlite3_column_int64(stmt_, c); }

double Statement::column_double(int c) const { return sqlite3_column_double(stmt_, c); }

std::string Statement::column_text(int c) const {
  const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, c));
  return text ? std::string(text, static_cast<size_t>(sqlite3_column_bytes(stmt_, c))) : "";
}

BlobView Statement::column_blob(int c) const {
  BlobView view;
  if (sqlite3_column_type(stmt_, c) == SQLITE_NULL) return view;
  view.data = sqlite3_column_blob(stmt_, c);
  view.size = static_cast<size_t>(sqlite3_column_bytes(stmt_, c));
  view.is_null = false;
  return view;
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
