#include "io_util.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>

namespace segmatch {
namespace io {
namespace detail {

namespace fs = std::filesystem;

void fail(const std::string& where, const std::string& problem) { throw IoError(where + ": " + problem); }

std::string line_ref(const std::string& path, size_t line_number) {
  return path + " line " + std::to_string(line_number);
}

namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

// Opens for reading with messages for the common failures (missing, directory, permissions).
FilePtr open_for_reading(const std::string& path) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) throw IoError("missing file: " + path);
  if (status.type() == fs::file_type::directory) fail(path, "is a directory, expected a file");
  FilePtr file(std::fopen(path.c_str(), "rb"));
  if (!file) fail(path, std::string("cannot open: ") + std::strerror(errno));
  return file;
}

std::string read_up_to(const std::string& path, size_t max_bytes) {
  FilePtr file = open_for_reading(path);
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  // Size unknown (pipe, special file): fall back to reading in chunks until EOF.
  const size_t hint = ec ? 0 : static_cast<size_t>(size);
  std::string data(std::min(hint, max_bytes), '\0');
  size_t got = data.empty() ? 0 : std::fread(&data[0], 1, data.size(), file.get());
  if (got < data.size() && std::ferror(file.get())) fail(path, "read error");
  data.resize(got);
  // The file may be longer than file_size said (it grew, or it is a special file).
  char chunk[65536];
  while (data.size() < max_bytes) {
    const size_t want = std::min(sizeof(chunk), max_bytes - data.size());
    const size_t n = std::fread(chunk, 1, want, file.get());
    data.append(chunk, n);
    if (n < want) break;
  }
  if (std::ferror(file.get())) fail(path, std::string("read error: ") + std::strerror(errno));
  return data;
}

}  // namespace

std::string read_file(const std::string& path) { return read_up_to(path, SIZE_MAX); }

std::string read_file_prefix(const std::string& path, size_t max_bytes) { return read_up_to(path, max_bytes); }

FileWriter::FileWriter(const std::string& path) : path_(path) {
  file_ = std::fopen(path.c_str(), "wb");
  if (!file_) fail_errno("cannot open for writing", errno);
}

FileWriter::~FileWriter() {
  if (file_) std::fclose(file_);  // only reached after an exception: nothing to report
}

void FileWriter::write(const void* data, size_t size) {
  if (size == 0) return;
  if (std::fwrite(data, 1, size, file_) != size) fail_errno("write failed", errno);
}

void FileWriter::close() {
  std::FILE* file = file_;
  file_ = nullptr;
  // fflush is where buffered data meets a full disk; fclose can still fail on NFS.
  const bool flushed = std::fflush(file) == 0;
  const int flush_errno = errno;
  const bool closed = std::fclose(file) == 0;
  if (!flushed) fail_errno("write failed", flush_errno);
  if (!closed) fail_errno("write failed on close", errno);
}

void FileWriter::fail_errno(const char* what, int error) {
  fail(path_, std::string(what) + ": " + std::strerror(error));
}

void write_file(const std::string& path, std::string_view content) {
  FileWriter writer(path);
  writer.write(content);
  writer.close();
}

std::string quote(std::string_view text) {
  constexpr size_t kMaxChars = 40;
  std::string out = "'";
  for (size_t i = 0; i < text.size() && i < kMaxChars; ++i) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    out += std::isprint(c) ? static_cast<char>(c) : '?';
  }
  if (text.size() > kMaxChars) out += "...";
  return out + "'";
}

bool parse_double(std::string_view token, double* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty()) return false;
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, *value);
  // Out-of-range values (1e999) are reported as errors rather than silently clamped.
  return result.ec == std::errc() && result.ptr == end;
}

namespace {
bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }
}  // namespace

void split_tokens(std::string_view line, std::vector<std::string_view>* tokens) {
  tokens->clear();
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && is_space(line[i])) ++i;
    const size_t begin = i;
    while (i < line.size() && !is_space(line[i])) ++i;
    if (i > begin) tokens->push_back(line.substr(begin, i - begin));
  }
}

std::string_view trim(std::string_view text) {
  while (!text.empty() && is_space(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_space(text.back())) text.remove_suffix(1);
  return text;
}

bool next_line(std::string_view* text, std::string_view* line) {
  if (text->empty()) return false;
  const size_t newline = text->find('\n');
  if (newline == std::string_view::npos) {
    *line = *text;
    *text = std::string_view();
  } else {
    *line = text->substr(0, newline);
    text->remove_prefix(newline + 1);
  }
  if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
  return true;
}

void parse_finite_numbers(const std::string& where, const std::vector<std::string_view>& tokens, size_t expected,
                          double* out) {
  if (tokens.size() != expected) {
    fail(where, "expected " + std::to_string(expected) + (expected == 1 ? " number" : " numbers") + ", got " +
                    std::to_string(tokens.size()));
  }
  for (size_t i = 0; i < expected; ++i) {
    if (!parse_double(tokens[i], &out[i])) fail(where, quote(tokens[i]) + " is not a number");
    if (!std::isfinite(out[i])) fail(where, "non-finite value " + quote(tokens[i]) + " (NaN/Inf)");
  }
}

void append_number(std::string* out, double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

void append_number(std::string* out, float value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out->append(buffer, result.ptr);
}

std::string extension_lower(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
