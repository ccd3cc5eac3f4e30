// The map file's schema (version kSchemaVersion) and the checks a file passes before the
// reader trusts it.
#pragma once

#include <sqlite3.h>
#include <sys/types.h>

#include <string>

namespace segmatch {
namespace storage {
namespace detail {

// Creates every table of an empty database (schema kSchemaVersion) and stamps application_id /
// user_version. Run inside the writer's transaction.
void create_schema(sqlite3* db, const std::string& path);

struct MapFileInfo {
  int schema_version = 0;
  dev_t device = 0;  // with inode: which file `path` named when it was checked
  ino_t inode = 0;
};
// Looks at the file itself before SQLite does, so that the common problems get a precise
// message: missing, not a regular file, empty, not SQLite, another application's database,
// unsupported schema version, truncated.
MapFileInfo check_map_file(const std::string& path);

// After opening: every table of the file's schema version is present and readable.
void check_tables(sqlite3* db, const std::string& path, int schema_version);

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
