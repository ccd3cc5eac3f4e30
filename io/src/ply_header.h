// Internal: the parsed header of a PLY file.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "scalar.h"

namespace segmatch {
namespace io {
namespace detail {

struct PlyProperty {
  std::string name;
  ScalarType type;  // the value type (list items for list properties)
  bool is_list = false;
  ScalarType count_type;  // list length type (list properties only)
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;

  bool has_lists() const;
  size_t fixed_stride() const;                // bytes per item; only meaningful without list properties
  int find(std::string_view property) const;  // index, or -1
};

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;  // first byte after the end_header line
};

PlyHeader parse_ply_header(const std::string& path, std::string_view file);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
