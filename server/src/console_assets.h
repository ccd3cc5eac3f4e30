// The operator's page's static files (server/console/), compiled into the binary by
// server/console/embed.cmake: the server reads no file at run time.
#pragma once

#include <cstddef>
#include <string>

namespace segmatch {
namespace server {

struct ConsoleAsset {
  const char* path;          // "/index.html"
  const char* content_type;  // with charset
  const unsigned char* data;
  size_t size;
};

// The file served at `path`, or null.
const ConsoleAsset* find_console_asset(const std::string& path);

}  // namespace server
}  // namespace segmatch
