// rosbag2 SQLite storage (.db3): tables topics(id, name, type, serialization_format, ...) and
// messages(id, topic_id, timestamp, data). Later rosbag2 versions add columns and tables
// (schema, metadata, topics.type_description_hash); only the columns named here are read.
// The file is opened read-only; a message's locator is its row id.
#include "bag_internal.h"

#include <sqlite3.h>

#include <filesystem>
#include <map>

namespace segmatch {
namespace io {
namespace detail {

namespace {

struct Statement {
  sqlite3_stmt* stmt = nullptr;
  ~Statement() { sqlite3_finalize(stmt); }
};

struct Topic {
  std::string name, type, format;
};

class Db3Reader final : public IndexedBag {
 public:
  explicit Db3Reader(const std::string& path);
  ~Db3Reader() override {
    sqlite3_finalize(data_query_);
    sqlite3_close(db_);
  }

  std::string data(const BagMessageRef& ref) const override;

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw IoError(path_ + ": " + what + ": " + sqlite3_errmsg(db_));
  }
  std::string text(sqlite3_stmt* stmt, int column) const {
    const unsigned char* t = sqlite3_column_text(stmt, column);
    return t ? std::string(reinterpret_cast<const char*>(t), sqlite3_column_bytes(stmt, column)) : "";
  }
  void prepare(const char* sql, sqlite3_stmt** stmt, const char* table) const;
  void read_topics();
  void read_messages();

  sqlite3* db_ = nullptr;
  sqlite3_stmt* data_query_ = nullptr;  // reused by data(): not thread-safe
  std::map<int64_t, Topic> topic_by_id_;
};

Db3Reader::Db3Reader(const std::string& path) : IndexedBag(path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw IoError(path + ": missing file (or not a file)");
  // Read-only: a bag being played must not be touched (no journal, no WAL checkpoint).
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    const std::string message = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw IoError(path + ": cannot open as SQLite: " + message);
  }
  try {
    read_topics();
    read_messages();
    prepare("SELECT topic_id, data FROM messages WHERE id = ?", &data_query_, "messages");
  } catch (...) {
    sqlite3_finalize(data_query_);
    sqlite3_close(db_);
    throw;
  }
}

void Db3Reader::prepare(const char* sql, sqlite3_stmt** stmt, const char* table) const {
  if (sqlite3_prepare_v2(db_, sql, -1, stmt, nullptr) != SQLITE_OK) {
    fail(std::string("table ") + table + " (not a rosbag2 SQLite bag?)");
  }
}

void Db3Reader::read_topics() {
  Statement q;
  prepare("SELECT id, name, type, serialization_format FROM topics ORDER BY id", &q.stmt, "topics");
  int rc;
  while ((rc = sqlite3_step(q.stmt)) == SQLITE_ROW) {
    const int64_t id = sqlite3_column_int64(q.stmt, 0);
    Topic topic{text(q.stmt, 1), text(q.stmt, 2), text(q.stmt, 3)};
    const bool repeated =
        std::any_of(topics_.begin(), topics_.end(), [&](const BagTopic& t) { return t.name == topic.name; });
    if (!repeated) topics_.push_back({topic.name, topic.type, 0});
    topic_by_id_[id] = std::move(topic);
  }
  if (rc != SQLITE_DONE) fail("table topics");
}

void Db3Reader::read_messages() {
  Statement q;
  // Ties in time keep the order of insertion (the row id), as the recorder received them.
  const std::string sql = "SELECT id, topic_id, timestamp, substr(data, 1, " + std::to_string(kBagHeadBytes) +
                          ") FROM messages ORDER BY timestamp, id";
  prepare(sql.c_str(), &q.stmt, "messages");
  int rc;
  while ((rc = sqlite3_step(q.stmt)) == SQLITE_ROW) {
    const int64_t row = sqlite3_column_int64(q.stmt, 0);
    const std::string where = path_ + ": table messages row " + std::to_string(row);
    const auto topic = topic_by_id_.find(sqlite3_column_int64(q.stmt, 1));
    if (topic == topic_by_id_.end()) {
      throw IoError(where + ": topic_id " + text(q.stmt, 1) + " is not in table topics");
    }
    if (sqlite3_column_type(q.stmt, 2) != SQLITE_INTEGER || sqlite3_column_int64(q.stmt, 2) < 0) {
      throw IoError(where + ": timestamp '" + text(q.stmt, 2) + "' is not a non-negative integer (ns)");
    }
    const uint64_t time = static_cast<uint64_t>(sqlite3_column_int64(q.stmt, 2));
    BagMessageRef ref{time, static_cast<uint64_t>(row), 0, 0, {}};
    if (const void* head = sqlite3_column_blob(q.stmt, 3))
      ref.head.assign(static_cast<const char*>(head), static_cast<size_t>(sqlite3_column_bytes(q.stmt, 3)));
    messages_[topic->second.name].push_back(std::move(ref));
  }
  if (rc != SQLITE_DONE) fail("table messages");
  for (BagTopic& t : topics_) t.messages = messages_[t.name].size();
}

std::string Db3Reader::data(const BagMessageRef& ref) const {
  const std::string where = path_ + ": table messages row " + std::to_string(static_cast<int64_t>(ref.a));
  sqlite3_reset(data_query_);
  sqlite3_bind_int64(data_query_, 1, static_cast<int64_t>(ref.a));
  const int rc = sqlite3_step(data_query_);
  if (rc == SQLITE_DONE) throw IoError(where + ": no such row");
  if (rc != SQLITE_ROW) fail("table messages row " + std::to_string(static_cast<int64_t>(ref.a)));
  const auto topic = topic_by_id_.find(sqlite3_column_int64(data_query_, 0));
  if (topic == topic_by_id_.end()) throw IoError(where + ": topic_id is not in table topics");
  if (topic->second.format != "cdr") {
    throw IoError(where + ": topic " + topic->second.name + " has serialization format '" + topic->second.format +
                  "': only cdr messages are read");
  }
  const void* blob = sqlite3_column_blob(data_query_, 1);
  const int size = sqlite3_column_bytes(data_query_, 1);
  std::string out = blob ? std::string(static_cast<const char*>(blob), static_cast<size_t>(size)) : "";
  sqlite3_reset(data_query_);
  return out;
}

}  // namespace

std::unique_ptr<BagReader> open_db3_file(const std::string& path) { return std::make_unique<Db3Reader>(path); }

}  // namespace detail
}  // namespace io
}  // namespace segmatch
