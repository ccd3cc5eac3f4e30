#include "segmatch/io/pose_io.h"

#include <sstream>

namespace segmatch {
namespace io {

Poses read_poses(const std::string& path) {
  std::istringstream in(read_file_bytes(path, "poses file"));
  for (std::string line; std::getline(in, line);) {
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream words(line);
    size_t columns = 0;
    for (std::string w; words >> w;) ++columns;
    if (columns == 12) return read_kitti_poses(path);
    if (columns == 8) return read_tum(path).poses;
    throw IoError(path + ": the first pose line has " + std::to_string(columns) +
                  " columns; expected 12 (KITTI: a row-major 3x4 matrix) or 8 (TUM: t x y z qx qy qz qw)");
  }
  throw IoError(path + ": no poses in the file");
}

}  // namespace io
}  // namespace segmatch
