// The single exception type of the io library.
//
// Every failure to read or write a file (missing, truncated, malformed, disk full) throws
// IoError, and its message names the file and the problem, so a user pointed at a broken
// dataset can fix it without a debugger.
#pragma once

#include <stdexcept>
#include <string>

namespace segmatch {
namespace io {

class IoError : public std::runtime_error {
 public:
  explicit IoError(const std::string& message) : std::runtime_error(message) {}
};

// The whole file as bytes. IoError "<path>: cannot open the <what>" or "<path>: read error".
std::string read_file_bytes(const std::string& path, const std::string& what = "file");

}  // namespace io
}  // namespace segmatch
