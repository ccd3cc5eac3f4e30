// PCD reader: header (pcd_header.cpp), then ascii, binary or binary_compressed data.
#include <algorithm>
#include <cstdint>
#include <cstring>

#include "cloud_internal.h"
#include "io_util.h"
#include "lzf.h"
#include "pcd_header.h"
#include "scalar.h"

namespace segmatch {
namespace io {

namespace {

using detail::fail;
using detail::PcdField;
using detail::PcdHeader;

// The fields the reader extracts; intensity and label are optional (nullptr).
struct Wanted {
  const PcdField* x;
  const PcdField* y;
  const PcdField* z;
  const PcdField* intensity;
  const PcdField* label;
};

Wanted wanted_fields(const PcdHeader& h) {
  const PcdField* intensity = h.find("intensity");
  if (!intensity) intensity = h.find("i");
  const PcdField* label = h.find("label");
  // Multi-valued fields cannot be a scalar intensity/label: treat them as extra fields.
  if (intensity && intensity->count != 1) intensity = nullptr;
  if (label && label->count != 1) label = nullptr;
  return {h.find("x"), h.find("y"), h.find("z"), intensity, label};
}

std::string bad_label(double v) {
  std::string text;
  detail::append_number(&text, v);
  return "label value " + text + " is not a valid uint32 label";
}

// Binary layouts differ only in where a field's value for point i lives: interleaved
// records (binary) or one array per field (binary_compressed, after decompression).
struct BinaryLayout {
  const uint8_t* data;
  size_t points;
  size_t point_size;
  bool per_field_arrays;

  const uint8_t* at(const PcdField& f, size_t i) const {
    if (per_field_arrays) return data + f.offset * points + i * static_cast<size_t>(f.type.size) * f.count;
    return data + i * point_size + f.offset;
  }
};

CloudData decode_binary(const std::string& path, const PcdHeader& h, const BinaryLayout& layout) {
  const Wanted w = wanted_fields(h);
  detail::CloudBuilder builder(h.points, w.intensity != nullptr, w.label != nullptr);
  for (size_t i = 0; i < h.points; ++i) {
    auto value = [&](const PcdField* f) { return detail::load_double(layout.at(*f, i), f->type, false); };
    const float intensity = w.intensity ? detail::to_float(value(w.intensity)) : 0.0f;
    uint32_t label = 0;
    if (w.label && !detail::to_label(value(w.label), w.label->type, &label)) {
      fail(path, "point " + std::to_string(i) + ": " + bad_label(value(w.label)));
    }
    builder.add(detail::to_float(value(w.x)), detail::to_float(value(w.y)), detail::to_float(value(w.z)), intensity,
                label);
  }
  return builder.finish();
}

size_t data_bytes(const std::string& path, const PcdHeader& h) {
  if (h.point_size != 0 && h.points > SIZE_MAX / h.point_size) {
    fail(path, "truncated: header declares " + std::to_string(h.points) + " points, more than any file can hold");
  }
  return h.points * h.point_size;
}

CloudData read_binary(const std::string& path, const std::string& file, const PcdHeader& h) {
  const size_t need = data_bytes(path, h);
  const size_t available = file.size() - h.data_offset;
  if (available < need) {
    fail(path, "truncated: header declares " + std::to_string(h.points) + " points (" + std::to_string(need) +
                   " bytes of data) but only " + std::to_string(available) + " bytes follow");
  }
  const auto* data = reinterpret_cast<const uint8_t*>(file.data()) + h.data_offset;
  return decode_binary(path, h, {data, h.points, h.point_size, false});
}

uint32_t read_u32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}

CloudData read_compressed(const std::string& path, const std::string& file, const PcdHeader& h) {
  const size_t need = data_bytes(path, h);
  const size_t available = file.size() - h.data_offset;
  if (available < 8) fail(path, "truncated: binary_compressed data has no size words");
  const auto* data = reinterpret_cast<const uint8_t*>(file.data()) + h.data_offset;
  const size_t compressed = read_u32(data);
  const size_t uncompressed = read_u32(data + 4);
  if (compressed > available - 8) {
    fail(path, "truncated: binary_compressed data declares " + std::to_string(compressed) +
                   " compressed bytes but only " + std::to_string(available - 8) + " follow");
  }
  if (uncompressed != need) {
    fail(path, "corrupt binary_compressed data: uncompressed size " + std::to_string(uncompressed) +
                   " bytes but header declares " + std::to_string(h.points) + " points of " +
                   std::to_string(h.point_size) + " bytes");
  }
  // LZF expands at most ~90x: refuse absurd sizes before allocating for them.
  if (need > compressed * 100 + 4096) {
    fail(path, "corrupt binary_compressed data: " + std::to_string(compressed) + " compressed bytes cannot hold " +
                   std::to_string(need) + " bytes");
  }
  std::vector<uint8_t> buffer(need);
  const std::string error = detail::lzf_decompress(data + 8, compressed, buffer.data(), need);
  if (!error.empty()) fail(path, "corrupt binary_compressed data: " + error);
  return decode_binary(path, h, {buffer.data(), h.points, h.point_size, true});
}

CloudData read_ascii(const std::string& path, const std::string& file, const PcdHeader& h) {
  const Wanted w = wanted_fields(h);
  // Do not trust POINTS for the reservation: a garbage header could ask for terabytes.
  const size_t max_lines = (file.size() - h.data_offset) / 2 + 1;
  detail::CloudBuilder builder(std::min(h.points, max_lines), w.intensity != nullptr, w.label != nullptr);
  std::string_view rest(file);
  rest.remove_prefix(h.data_offset);
  std::string_view line;
  std::vector<std::string_view> tokens;
  size_t line_number = h.data_line;
  size_t read = 0;
  while (read < h.points && detail::next_line(&rest, &line)) {
    ++line_number;
    detail::split_tokens(line, &tokens);
    if (tokens.empty()) continue;
    const std::string where = detail::line_ref(path, line_number);
    if (tokens.size() != h.values_per_point) {
      fail(where, "expected " + std::to_string(h.values_per_point) + " values, got " + std::to_string(tokens.size()));
    }
    auto value = [&](const PcdField* f) {
      double v = 0.0;
      if (!detail::parse_double(tokens[f->token_index], &v)) {
        fail(where, "field " + f->name + ": " + detail::quote(tokens[f->token_index]) + " is not a number");
      }
      return v;
    };
    const float intensity = w.intensity ? detail::to_float(value(w.intensity)) : 0.0f;
    uint32_t label = 0;
    if (w.label && !detail::to_label(value(w.label), w.label->type, &label)) fail(where, bad_label(value(w.label)));
    builder.add(detail::to_float(value(w.x)), detail::to_float(value(w.y)), detail::to_float(value(w.z)), intensity,
                label);
    ++read;
  }
  if (read < h.points) {
    fail(path, "truncated: header declares " + std::to_string(h.points) + " points but only " + std::to_string(read) +
                   " data lines follow");
  }
  return builder.finish();
}

}  // namespace

CloudData read_pcd(const std::string& path) {
  const std::string file = detail::read_file(path);
  const PcdHeader header = detail::parse_pcd_header(path, file);
  if (header.data == "ascii") return read_ascii(path, file, header);
  if (header.data == "binary") return read_binary(path, file, header);
  return read_compressed(path, file, header);
}

namespace detail {

bool pcd_has_field(const std::string& path, const std::string& field) {
  // Headers are a few hundred bytes; 64 KiB leaves room for thousands of fields.
  const std::string prefix = read_file_prefix(path, 1 << 16);
  return parse_pcd_header(path, prefix).find(field) != nullptr;
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
