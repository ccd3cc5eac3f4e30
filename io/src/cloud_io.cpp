// Format dispatch by file extension.
#include <segmatch/io/cloud_io.h>

#include "io_util.h"

namespace segmatch {
namespace io {

namespace {

[[noreturn]] void unknown_extension(const std::string& path, const std::string& ext) {
  detail::fail(path, "unknown point-cloud extension " + detail::quote(ext) + " (expected .bin, .pcd or .ply)");
}

}  // namespace

CloudData read_cloud(const std::string& path) {
  const std::string ext = detail::extension_lower(path);
  if (ext == ".bin") return read_kitti_bin(path);
  if (ext == ".pcd") return read_pcd(path);
  if (ext == ".ply") return read_ply(path);
  unknown_extension(path, ext);
}

void write_cloud(const std::string& path, const PointCloud& cloud) {
  const std::string ext = detail::extension_lower(path);
  if (ext == ".bin") return write_kitti_bin(path, cloud);
  if (ext == ".pcd") return write_pcd(path, cloud);
  if (ext == ".ply") return write_ply(path, cloud);
  unknown_extension(path, ext);
}

}  // namespace io
}  // namespace segmatch
