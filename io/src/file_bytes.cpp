#include "segmatch/io/error.h"

#include <fstream>
#include <sstream>

namespace segmatch {
namespace io {

std::string read_file_bytes(const std::string& path, const std::string& what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open the " + what);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  if (in.bad()) throw IoError(path + ": read error");
  return bytes.str();
}

}  // namespace io
}  // namespace segmatch
