// Internal: the parsed header of a PCD file.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "scalar.h"

namespace segmatch {
namespace io {
namespace detail {

struct PcdField {
  std::string name;
  ScalarType type;
  size_t count = 1;
  size_t offset = 0;       // byte offset inside an interleaved (binary) record
  size_t token_index = 0;  // index of its first value on an ascii data line
};

struct PcdHeader {
  std::vector<PcdField> fields;
  size_t points = 0;
  size_t point_size = 0;        // bytes per binary record
  size_t values_per_point = 0;  // tokens per ascii line
  std::string data;             // "ascii", "binary" or "binary_compressed"
  size_t data_offset = 0;       // first byte after the DATA line
  size_t data_line = 0;         // line number of the DATA line (for ascii error messages)

  // The field with that name, or nullptr.
  const PcdField* find(std::string_view name) const;
};

// Parses and validates the header at the start of `file`; `path` is for messages.
PcdHeader parse_pcd_header(const std::string& path, std::string_view file);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
