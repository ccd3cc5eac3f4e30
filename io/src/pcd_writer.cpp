// PCD writer: x y z intensity (F4) [+ label (U4)], in the layout PCL writes.
#include <segmatch/io/cloud_io.h>

#include <cstdint>
#include <cstring>

#include "io_util.h"
#include "lzf.h"

namespace segmatch {
namespace io {

namespace {

std::string header(size_t points, bool with_labels, const char* encoding) {
  const std::string n = std::to_string(points);
  std::string h = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n";
  h += with_labels ? "FIELDS x y z intensity label\nSIZE 4 4 4 4 4\nTYPE F F F F U\nCOUNT 1 1 1 1 1\n"
                   : "FIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n";
  h += "WIDTH " + n + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + n + "\nDATA " + encoding + "\n";
  return h;
}

std::string ascii_body(const PointCloud& cloud, const std::vector<uint32_t>* labels) {
  std::string body;
  body.reserve(cloud.size() * 48);
  for (size_t i = 0; i < cloud.size(); ++i) {
    const Point& p = cloud[i];
    for (float v : {p.x, p.y, p.z, p.intensity}) {
      detail::append_number(&body, v);
      body += ' ';
    }
    if (labels) body += std::to_string((*labels)[i]) + ' ';
    body.back() = '\n';
  }
  return body;
}

// Interleaved records; without labels the in-memory cloud already has the file layout.
std::vector<uint8_t> interleaved(const PointCloud& cloud, const std::vector<uint32_t>& labels) {
  constexpr size_t kRecord = sizeof(Point) + sizeof(uint32_t);
  std::vector<uint8_t> data(cloud.size() * kRecord);
  for (size_t i = 0; i < cloud.size(); ++i) {
    std::memcpy(&data[i * kRecord], &cloud[i], sizeof(Point));
    std::memcpy(&data[i * kRecord + sizeof(Point)], &labels[i], sizeof(uint32_t));
  }
  return data;
}

// binary_compressed stores one array per field (x x x.. y y y..), which compresses better.
std::vector<uint8_t> per_field_arrays(const PointCloud& cloud, const std::vector<uint32_t>* labels) {
  const size_t n = cloud.size();
  const size_t fields = labels ? 5 : 4;
  std::vector<uint8_t> data(n * fields * 4);
  for (size_t i = 0; i < n; ++i) {
    const float values[4] = {cloud[i].x, cloud[i].y, cloud[i].z, cloud[i].intensity};
    for (size_t f = 0; f < 4; ++f) std::memcpy(&data[(f * n + i) * 4], &values[f], 4);
    if (labels) std::memcpy(&data[(4 * n + i) * 4], &(*labels)[i], 4);
  }
  return data;
}

void write_compressed(const std::string& path, detail::FileWriter* writer, const std::vector<uint8_t>& raw) {
  const std::vector<uint8_t> packed = detail::lzf_compress(raw.data(), raw.size());
  if (raw.size() > UINT32_MAX || packed.size() > UINT32_MAX) {
    detail::fail(path, "cloud too large for binary_compressed PCD (sizes are 32-bit)");
  }
  const uint32_t sizes[2] = {static_cast<uint32_t>(packed.size()), static_cast<uint32_t>(raw.size())};
  writer->write(sizes, sizeof(sizes));
  writer->write(packed.data(), packed.size());
}

const char* encoding_name(PcdEncoding encoding) {
  switch (encoding) {
    case PcdEncoding::kAscii: return "ascii";
    case PcdEncoding::kBinary: return "binary";
    case PcdEncoding::kBinaryCompressed: return "binary_compressed";
  }
  return "binary";
}

}  // namespace

void write_pcd(const std::string& path, const PointCloud& cloud, PcdEncoding encoding,
               const std::vector<uint32_t>* labels) {
  if (labels && labels->size() != cloud.size()) {
    detail::fail(path, "cannot write " + std::to_string(labels->size()) + " labels for " +
                           std::to_string(cloud.size()) + " points");
  }
  detail::FileWriter writer(path);
  writer.write(header(cloud.size(), labels != nullptr, encoding_name(encoding)));
  if (encoding == PcdEncoding::kAscii) {
    writer.write(ascii_body(cloud, labels));
  } else if (encoding == PcdEncoding::kBinaryCompressed) {
    write_compressed(path, &writer, per_field_arrays(cloud, labels));
  } else if (labels) {
    const std::vector<uint8_t> data = interleaved(cloud, *labels);
    writer.write(data.data(), data.size());
  } else {
    writer.write(cloud.data(), cloud.size() * sizeof(Point));
  }
  writer.close();
}

}  // namespace io
}  // namespace segmatch
