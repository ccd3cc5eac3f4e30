// KITTI velodyne .bin scans and SemanticKITTI .label files: raw little-endian arrays.
#include <cstring>

#include "cloud_internal.h"
#include "io_util.h"
#include "scalar.h"

namespace segmatch {
namespace io {

// The formats are little-endian and are read by memcpy, so a big-endian host would need
// byte swaps everywhere; no supported platform is big-endian.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "io assumes a little-endian host");

namespace {

constexpr size_t kRecordBytes = sizeof(Point);  // x y z intensity, float32 each

size_t record_count(const std::string& path, const std::string& data) {
  if (data.size() % kRecordBytes != 0) {
    detail::fail(path, "truncated or not a KITTI scan: size " + std::to_string(data.size()) +
                           " bytes is not a multiple of 16 (float32 x y z intensity records)");
  }
  return data.size() / kRecordBytes;
}

CloudData decode(const std::string& data, size_t count, const std::vector<uint32_t>* labels) {
  detail::CloudBuilder builder(count, /*has_intensity=*/true, labels != nullptr);
  for (size_t i = 0; i < count; ++i) {
    Point p;
    std::memcpy(&p, data.data() + i * kRecordBytes, kRecordBytes);
    builder.add(p.x, p.y, p.z, p.intensity, labels ? (*labels)[i] : 0u);
  }
  return builder.finish();
}

}  // namespace

CloudData read_kitti_bin(const std::string& path) {
  const std::string data = detail::read_file(path);
  return decode(data, record_count(path, data), nullptr);
}

void write_kitti_bin(const std::string& path, const PointCloud& cloud) {
  detail::FileWriter writer(path);
  writer.write(cloud.data(), cloud.size() * kRecordBytes);  // Point has the record layout
  writer.close();
}

std::vector<uint32_t> read_kitti_labels(const std::string& path) {
  const std::string data = detail::read_file(path);
  if (data.size() % sizeof(uint32_t) != 0) {
    detail::fail(path, "truncated or not a label file: size " + std::to_string(data.size()) +
                           " bytes is not a multiple of 4 (uint32 labels)");
  }
  std::vector<uint32_t> labels(data.size() / sizeof(uint32_t));
  if (!labels.empty()) std::memcpy(labels.data(), data.data(), data.size());
  return labels;
}

void write_kitti_labels(const std::string& path, const std::vector<uint32_t>& labels) {
  detail::FileWriter writer(path);
  writer.write(labels.data(), labels.size() * sizeof(uint32_t));
  writer.close();
}

namespace detail {

CloudData read_kitti_bin_labeled(const std::string& bin_path, const std::string& label_path) {
  const std::string data = read_file(bin_path);
  const size_t count = record_count(bin_path, data);
  const std::vector<uint32_t> labels = read_kitti_labels(label_path);
  if (labels.size() != count) {
    fail(label_path, "has " + std::to_string(labels.size()) + " labels but " + bin_path + " has " +
                         std::to_string(count) + " points");
  }
  return decode(data, count, &labels);
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
