// PLY header parsing: "ply", "format ...", then element/property declarations, comments and
// obj_info lines, up to "end_header".
#include "ply_header.h"

#include <charconv>

#include "io_util.h"

namespace segmatch {
namespace io {
namespace detail {

namespace {

constexpr size_t kMaxProperties = 4096;

bool parse_type(std::string_view name, ScalarType* t) {
  struct Entry {
    const char* a;
    const char* b;
    ScalarKind kind;
    int size;
  };
  static const Entry kTypes[] = {
      {"char", "int8", ScalarKind::kSigned, 1},    {"uchar", "uint8", ScalarKind::kUnsigned, 1},
      {"short", "int16", ScalarKind::kSigned, 2},  {"ushort", "uint16", ScalarKind::kUnsigned, 2},
      {"int", "int32", ScalarKind::kSigned, 4},    {"uint", "uint32", ScalarKind::kUnsigned, 4},
      {"float", "float32", ScalarKind::kFloat, 4}, {"double", "float64", ScalarKind::kFloat, 8},
      {"int64", "long", ScalarKind::kSigned, 8},   {"uint64", "ulong", ScalarKind::kUnsigned, 8},
  };
  for (const Entry& e : kTypes) {
    if (name == e.a || name == e.b) {
      *t = {e.kind, e.size};
      return true;
    }
  }
  return false;
}

ScalarType type_or_fail(const std::string& where, std::string_view name) {
  ScalarType t;
  if (!parse_type(name, &t)) fail(where, "unknown property type " + quote(name));
  return t;
}

void parse_format(const std::string& where, const std::vector<std::string_view>& tokens, PlyHeader* header) {
  if (tokens.size() != 3) fail(where, "malformed format line");
  if (tokens[1] == "ascii")
    header->format = PlyFormat::kAscii;
  else if (tokens[1] == "binary_little_endian")
    header->format = PlyFormat::kBinaryLittleEndian;
  else if (tokens[1] == "binary_big_endian")
    header->format = PlyFormat::kBinaryBigEndian;
  else
    fail(where, "unknown format " + quote(tokens[1]));
}

void parse_element(const std::string& where, const std::vector<std::string_view>& tokens, PlyHeader* header) {
  if (tokens.size() != 3) fail(where, "malformed element line (expected: element <name> <count>)");
  PlyElement element;
  element.name = std::string(tokens[1]);
  const std::string_view n = tokens[2];
  const auto r = std::from_chars(n.data(), n.data() + n.size(), element.count);
  if (r.ec != std::errc() || r.ptr != n.data() + n.size()) {
    fail(where, "element count " + quote(n) + " is not a non-negative integer");
  }
  header->elements.push_back(std::move(element));
}

void parse_property(const std::string& where, const std::vector<std::string_view>& tokens, PlyHeader* header) {
  if (header->elements.empty()) fail(where, "property declared before any element");
  PlyElement& element = header->elements.back();
  if (element.properties.size() >= kMaxProperties) fail(where, "too many properties");
  PlyProperty p;
  if (tokens.size() == 5 && tokens[1] == "list") {
    p.is_list = true;
    p.count_type = type_or_fail(where, tokens[2]);
    if (p.count_type.kind == ScalarKind::kFloat) fail(where, "list count type must be an integer type");
    p.type = type_or_fail(where, tokens[3]);
    p.name = std::string(tokens[4]);
  } else if (tokens.size() == 3) {
    p.type = type_or_fail(where, tokens[1]);
    p.name = std::string(tokens[2]);
  } else {
    fail(where, "malformed property line");
  }
  element.properties.push_back(std::move(p));
}

}  // namespace

bool PlyElement::has_lists() const {
  for (const PlyProperty& p : properties) {
    if (p.is_list) return true;
  }
  return false;
}

size_t PlyElement::fixed_stride() const {
  size_t stride = 0;
  for (const PlyProperty& p : properties) stride += static_cast<size_t>(p.type.size);
  return stride;
}

int PlyElement::find(std::string_view property) const {
  for (size_t i = 0; i < properties.size(); ++i) {
    if (properties[i].name == property) return static_cast<int>(i);
  }
  return -1;
}

PlyHeader parse_ply_header(const std::string& path, std::string_view file) {
  std::string_view rest = file;
  std::string_view line;
  if (!next_line(&rest, &line) || trim(line) != "ply") {
    fail(path, "not a PLY file: missing 'ply' magic on the first line");
  }
  PlyHeader header;
  bool has_format = false;
  std::vector<std::string_view> tokens;
  for (size_t line_number = 2; next_line(&rest, &line); ++line_number) {
    const std::string where = line_ref(path, line_number);
    split_tokens(line, &tokens);
    if (tokens.empty() || tokens[0] == "comment" || tokens[0] == "obj_info") continue;
    if (tokens[0] == "end_header") {
      if (!has_format) fail(path, "header has no format line");
      header.data_offset = file.size() - rest.size();
      return header;
    }
    if (tokens[0] == "format") {
      parse_format(where, tokens, &header);
      has_format = true;
    } else if (tokens[0] == "element") {
      parse_element(where, tokens, &header);
    } else if (tokens[0] == "property") {
      parse_property(where, tokens, &header);
    } else {
      fail(where, "garbage in header: unknown keyword " + quote(tokens[0]));
    }
  }
  fail(path, "truncated or garbage header: no end_header line");
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
