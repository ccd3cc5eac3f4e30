// PLY writer: one "vertex" element with float x y z intensity.
#include <segmatch/io/cloud_io.h>

#include "io_util.h"

namespace segmatch {
namespace io {

void write_ply(const std::string& path, const PointCloud& cloud, PlyEncoding encoding) {
  const bool ascii = encoding == PlyEncoding::kAscii;
  std::string text = "ply\nformat ";
  text += ascii ? "ascii" : "binary_little_endian";
  text += " 1.0\ncomment written by segmatch\nelement vertex " + std::to_string(cloud.size()) +
          "\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\n"
          "end_header\n";
  detail::FileWriter writer(path);
  if (!ascii) {
    writer.write(text);
    writer.write(cloud.data(), cloud.size() * sizeof(Point));  // Point is the vertex record
    writer.close();
    return;
  }
  text.reserve(text.size() + cloud.size() * 48);
  for (const Point& p : cloud) {
    for (float v : {p.x, p.y, p.z, p.intensity}) {
      detail::append_number(&text, v);
      text += ' ';
    }
    text.back() = '\n';
  }
  writer.write(text);
  writer.close();
}

}  // namespace io
}  // namespace segmatch
