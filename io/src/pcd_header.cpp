// PCD header parsing. The header is text, one "KEYWORD values..." line each, ending with the
// DATA line; the (possibly binary) data starts right after that line's newline.
#include "pcd_header.h"

#include <charconv>
#include <limits>

#include "io_util.h"

namespace segmatch {
namespace io {
namespace detail {

namespace {

// Bounds that no real cloud reaches but that keep size arithmetic far from overflow on
// garbage headers.
constexpr size_t kMaxFields = 4096;
constexpr size_t kMaxCount = 1 << 20;

struct RawHeader {
  std::vector<std::string_view> fields, sizes, types, counts;
  bool has_width = false, has_points = false;
  size_t width = 0, height = 1, points = 0;
  std::string data;
};

size_t parse_size(const std::string& where, std::string_view keyword, std::string_view token) {
  size_t value = 0;
  const auto r = std::from_chars(token.data(), token.data() + token.size(), value);
  if (r.ec != std::errc() || r.ptr != token.data() + token.size()) {
    fail(where, std::string(keyword) + " value " + quote(token) + " is not a non-negative integer");
  }
  return value;
}

size_t single_size(const std::string& where, const std::vector<std::string_view>& tokens) {
  if (tokens.size() != 2) fail(where, std::string(tokens[0]) + " expects one value");
  return parse_size(where, tokens[0], tokens[1]);
}

// Applies one header line; returns true for the DATA line, which ends the header.
bool apply_line(const std::string& where, const std::vector<std::string_view>& tokens, RawHeader* raw) {
  const std::string_view key = tokens[0];
  const std::vector<std::string_view> values(tokens.begin() + 1, tokens.end());
  if (key == "FIELDS" || key == "COLUMNS") {
    raw->fields = values;
  } else if (key == "SIZE") {
    raw->sizes = values;
  } else if (key == "TYPE") {
    raw->types = values;
  } else if (key == "COUNT") {
    raw->counts = values;
  } else if (key == "WIDTH") {
    raw->width = single_size(where, tokens);
    raw->has_width = true;
  } else if (key == "HEIGHT") {
    raw->height = single_size(where, tokens);
  } else if (key == "POINTS") {
    raw->points = single_size(where, tokens);
    raw->has_points = true;
  } else if (key == "DATA") {
    if (tokens.size() != 2) fail(where, "DATA expects one value");
    raw->data = std::string(tokens[1]);
    if (raw->data != "ascii" && raw->data != "binary" && raw->data != "binary_compressed") {
      fail(where, "unsupported DATA encoding " + quote(tokens[1]) + " (expected ascii, binary or binary_compressed)");
    }
    return true;
  } else if (key != "VERSION" && key != "VIEWPOINT") {  // those two carry nothing we need
    fail(where, "not a PCD header line: " + quote(key) + " is not a PCD keyword");
  }
  return false;
}

ScalarType parse_type(const std::string& path, std::string_view type, std::string_view size, std::string_view field) {
  ScalarType t;
  if (type == "F")
    t.kind = ScalarKind::kFloat;
  else if (type == "U")
    t.kind = ScalarKind::kUnsigned;
  else if (type == "I")
    t.kind = ScalarKind::kSigned;
  else
    fail(path, "field " + quote(field) + " has unknown TYPE " + quote(type));
  const size_t bytes = parse_size(path, "SIZE", size);
  t.size = bytes <= 8 ? static_cast<int>(bytes) : 0;
  if (!is_valid(t)) {
    fail(path, "field " + quote(field) + " has unsupported TYPE/SIZE " + std::string(type) + std::string(size));
  }
  return t;
}

void build_fields(const std::string& path, const RawHeader& raw, PcdHeader* header) {
  const size_t n = raw.fields.size();
  if (n == 0) fail(path, "header has no FIELDS line");
  if (n > kMaxFields) fail(path, "header declares too many fields");
  if (raw.sizes.size() != n || raw.types.size() != n || (!raw.counts.empty() && raw.counts.size() != n)) {
    fail(path, "header is inconsistent: " + std::to_string(n) + " FIELDS but " + std::to_string(raw.sizes.size()) +
                   " SIZE, " + std::to_string(raw.types.size()) + " TYPE and " + std::to_string(raw.counts.size()) +
                   " COUNT values");
  }
  for (size_t i = 0; i < n; ++i) {
    PcdField f;
    f.name = std::string(raw.fields[i]);
    f.type = parse_type(path, raw.types[i], raw.sizes[i], raw.fields[i]);
    f.count = raw.counts.empty() ? 1 : parse_size(path, "COUNT", raw.counts[i]);
    if (f.count == 0 || f.count > kMaxCount) {
      fail(path, "field " + quote(f.name) + " has invalid COUNT " + std::to_string(f.count));
    }
    f.offset = header->point_size;
    f.token_index = header->values_per_point;
    header->point_size += f.count * static_cast<size_t>(f.type.size);
    header->values_per_point += f.count;
    header->fields.push_back(std::move(f));
  }
}

size_t point_count(const std::string& path, const RawHeader& raw) {
  if (!raw.has_width && !raw.has_points) fail(path, "header has neither WIDTH nor POINTS");
  if (!raw.has_width) return raw.points;
  if (raw.height != 0 && raw.width > std::numeric_limits<size_t>::max() / raw.height) {
    fail(path, "header WIDTH x HEIGHT overflows");
  }
  const size_t organized = raw.width * raw.height;
  if (raw.has_points && raw.points != organized) {
    fail(path, "header is inconsistent: POINTS " + std::to_string(raw.points) +
                   " but WIDTH x HEIGHT = " + std::to_string(organized));
  }
  return organized;
}

void check_xyz(const std::string& path, const PcdHeader& header) {
  for (const char* name : {"x", "y", "z"}) {
    const PcdField* f = header.find(name);
    if (!f) {
      std::string names;
      for (const PcdField& field : header.fields) names += (names.empty() ? "" : " ") + field.name;
      fail(path, std::string("missing field ") + name + " (fields: " + names + ")");
    }
    if (f->count != 1)
      fail(path, std::string("field ") + name + " has COUNT " + std::to_string(f->count) + ", expected 1");
  }
}

}  // namespace

const PcdField* PcdHeader::find(std::string_view name) const {
  for (const PcdField& f : fields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

PcdHeader parse_pcd_header(const std::string& path, std::string_view file) {
  RawHeader raw;
  std::string_view rest = file;
  std::string_view line;
  std::vector<std::string_view> tokens;
  size_t line_number = 0;
  bool done = false;
  while (!done && next_line(&rest, &line)) {
    ++line_number;
    split_tokens(line, &tokens);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    done = apply_line(line_ref(path, line_number), tokens, &raw);
  }
  if (!done) fail(path, "truncated or not a PCD file: header has no DATA line");
  PcdHeader header;
  build_fields(path, raw, &header);
  header.points = point_count(path, raw);
  header.data = raw.data;
  header.data_offset = file.size() - rest.size();
  header.data_line = line_number;
  check_xyz(path, header);
  return header;
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
