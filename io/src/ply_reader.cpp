// PLY reader. Elements are stored one after the other in header order, so every element
// before "vertex" has to be walked (list properties make items variable-sized); elements
// after it are never looked at.
#include <algorithm>
#include <cctype>
#include <cstdint>

#include "io_util.h"
#include "ply_header.h"
#include "scalar.h"

namespace segmatch {
namespace io {

namespace {

using detail::fail;
using detail::PlyElement;
using detail::PlyHeader;
using detail::PlyProperty;

// Property indices of the vertex element; -1 when absent.
struct VertexFields {
  int x, y, z, intensity, label;
};

int scalar_property(const PlyElement& e, std::string_view a, std::string_view b = {}) {
  int k = e.find(a);
  if (k < 0 && !b.empty()) k = e.find(b);
  return (k >= 0 && !e.properties[k].is_list) ? k : -1;
}

VertexFields vertex_fields(const std::string& path, const PlyElement& e) {
  VertexFields f{scalar_property(e, "x"), scalar_property(e, "y"), scalar_property(e, "z"),
                 scalar_property(e, "intensity", "scalar_intensity"), scalar_property(e, "label", "scalar_label")};
  const int indices[3] = {f.x, f.y, f.z};
  for (int axis = 0; axis < 3; ++axis) {
    if (indices[axis] < 0) {
      fail(path, std::string("vertex element has no scalar property ") + "xyz"[axis]);
    }
  }
  return f;
}

[[noreturn]] void truncated(const std::string& path, const PlyElement& e, size_t item) {
  fail(path, "truncated: data ends inside element '" + e.name + "' item " + std::to_string(item) + " of " +
                 std::to_string(e.count));
}

// Cursor over binary data; every access is bounds-checked because the header is untrusted.
struct Binary {
  const uint8_t* data;
  size_t size;
  size_t pos;
  bool swap;
};

// Advances over one item, recording where each scalar property starts (when offsets != null).
void walk_item(const std::string& path, const PlyElement& e, size_t item, Binary* in, std::vector<size_t>* offsets) {
  for (size_t k = 0; k < e.properties.size(); ++k) {
    const PlyProperty& p = e.properties[k];
    if (!p.is_list) {
      if (in->size - in->pos < static_cast<size_t>(p.type.size)) truncated(path, e, item);
      if (offsets) (*offsets)[k] = in->pos;
      in->pos += static_cast<size_t>(p.type.size);
      continue;
    }
    if (in->size - in->pos < static_cast<size_t>(p.count_type.size)) truncated(path, e, item);
    const int64_t n = detail::load_integer(in->data + in->pos, p.count_type, in->swap);
    in->pos += static_cast<size_t>(p.count_type.size);
    if (n < 0) fail(path, "corrupt data: negative list length in element '" + e.name + "'");
    if (static_cast<uint64_t>(n) > (in->size - in->pos) / static_cast<size_t>(p.type.size)) {
      truncated(path, e, item);
    }
    in->pos += static_cast<size_t>(n) * static_cast<size_t>(p.type.size);
  }
}

// Bytes of a list-free element, or a "truncated" error when the file is shorter.
size_t fixed_bytes(const std::string& path, const PlyElement& e, const Binary& in) {
  const size_t stride = e.fixed_stride();
  const size_t available = in.size - in.pos;
  if (stride != 0 && e.count > available / stride) {
    const std::string need = e.count > SIZE_MAX / stride ? "more than any file can hold"
                                                         : std::to_string(e.count * stride) + " bytes of data";
    fail(path, "truncated: header declares " + std::to_string(e.count) + " " + e.name + " items (" + need +
                   ") but only " + std::to_string(available) + " bytes follow");
  }
  return e.count * stride;
}

void skip_binary(const std::string& path, const PlyElement& e, Binary* in) {
  if (!e.has_lists()) {
    in->pos += fixed_bytes(path, e, *in);
    return;
  }
  for (size_t i = 0; i < e.count; ++i) walk_item(path, e, i, in, nullptr);
}

CloudData read_vertices_binary(const std::string& path, const PlyElement& e, Binary* in) {
  const VertexFields f = vertex_fields(path, e);
  const bool fixed = !e.has_lists();
  if (fixed) fixed_bytes(path, e, *in);  // up-front truncation check with the byte counts
  std::vector<size_t> offsets(e.properties.size(), 0);
  if (fixed) {
    for (size_t k = 1; k < offsets.size(); ++k) offsets[k] = offsets[k - 1] + e.properties[k - 1].type.size;
  }
  const size_t stride = e.fixed_stride();
  detail::CloudBuilder builder(std::min(e.count, (in->size - in->pos) / 3 + 1), f.intensity >= 0, f.label >= 0);
  for (size_t i = 0; i < e.count; ++i) {
    const size_t base = fixed ? in->pos + i * stride : 0;
    if (!fixed) walk_item(path, e, i, in, &offsets);
    auto value = [&](int k) {
      return detail::load_double(in->data + base + offsets[k], e.properties[k].type, in->swap);
    };
    uint32_t label = 0;
    if (f.label >= 0 && !detail::to_label(value(f.label), e.properties[f.label].type, &label)) {
      fail(path, "vertex " + std::to_string(i) + ": label is not a valid uint32");
    }
    builder.add(detail::to_float(value(f.x)), detail::to_float(value(f.y)), detail::to_float(value(f.z)),
                f.intensity >= 0 ? detail::to_float(value(f.intensity)) : 0.0f, label);
  }
  return builder.finish();
}

// Whitespace-separated tokens of an ascii body (items need not be one per line).
struct Tokens {
  std::string_view rest;

  bool next(std::string_view* token) {
    size_t i = 0;
    while (i < rest.size() && std::isspace(static_cast<unsigned char>(rest[i]))) ++i;
    size_t j = i;
    while (j < rest.size() && !std::isspace(static_cast<unsigned char>(rest[j]))) ++j;
    *token = rest.substr(i, j - i);
    rest.remove_prefix(j);
    return !token->empty();
  }
};

double ascii_number(const std::string& path, const PlyElement& e, size_t item, Tokens* in) {
  std::string_view token;
  if (!in->next(&token)) truncated(path, e, item);
  double v = 0.0;
  if (!detail::parse_double(token, &v)) {
    fail(path,
         "element '" + e.name + "' item " + std::to_string(item) + ": " + detail::quote(token) + " is not a number");
  }
  return v;
}

// Reads one ascii item; scalar values go to values[k], list properties are skipped.
void ascii_item(const std::string& path, const PlyElement& e, size_t item, Tokens* in, std::vector<double>* values) {
  for (size_t k = 0; k < e.properties.size(); ++k) {
    const double v = ascii_number(path, e, item, in);
    if (!e.properties[k].is_list) {
      (*values)[k] = v;
      continue;
    }
    if (!(v >= 0.0 && v <= 1e9) || v != static_cast<double>(static_cast<size_t>(v))) {
      fail(path, "element '" + e.name + "' item " + std::to_string(item) + ": invalid list length");
    }
    std::string_view skipped;
    for (size_t n = static_cast<size_t>(v); n > 0; --n) {
      if (!in->next(&skipped)) truncated(path, e, item);
    }
  }
}

CloudData read_ascii(const std::string& path, const PlyHeader& h, std::string_view body) {
  Tokens in{body};
  std::vector<double> values;
  for (const PlyElement& e : h.elements) {
    values.assign(e.properties.size(), 0.0);
    if (e.name != "vertex") {
      // An element without properties has no tokens to read, whatever its count (found by
      // fuzzing: a count of 4e12 spun here).
      if (!e.properties.empty())
        for (size_t i = 0; i < e.count; ++i) ascii_item(path, e, i, &in, &values);
      continue;
    }
    const VertexFields f = vertex_fields(path, e);
    detail::CloudBuilder builder(std::min(e.count, body.size() / 6 + 1), f.intensity >= 0, f.label >= 0);
    for (size_t i = 0; i < e.count; ++i) {
      ascii_item(path, e, i, &in, &values);
      uint32_t label = 0;
      if (f.label >= 0 && !detail::to_label(values[f.label], e.properties[f.label].type, &label)) {
        fail(path, "vertex " + std::to_string(i) + ": label is not a valid uint32");
      }
      builder.add(detail::to_float(values[f.x]), detail::to_float(values[f.y]), detail::to_float(values[f.z]),
                  f.intensity >= 0 ? detail::to_float(values[f.intensity]) : 0.0f, label);
    }
    return builder.finish();
  }
  fail(path, "no vertex element in the header");
}

CloudData read_binary(const std::string& path, const PlyHeader& h, const std::string& file) {
  Binary in{reinterpret_cast<const uint8_t*>(file.data()), file.size(), h.data_offset,
            h.format == detail::PlyFormat::kBinaryBigEndian};
  for (const PlyElement& e : h.elements) {
    if (e.name == "vertex") return read_vertices_binary(path, e, &in);
    skip_binary(path, e, &in);
  }
  fail(path, "no vertex element in the header");
}

}  // namespace

CloudData read_ply(const std::string& path) {
  const std::string file = detail::read_file(path);
  const PlyHeader header = detail::parse_ply_header(path, file);
  if (header.format == detail::PlyFormat::kAscii) {
    return read_ascii(path, header, std::string_view(file).substr(header.data_offset));
  }
  return read_binary(path, header, file);
}

}  // namespace io
}  // namespace segmatch
