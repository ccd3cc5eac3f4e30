// Internal helpers shared by the readers and writers: whole-file reads, checked writes,
// error messages and fast text parsing. Not installed; include only from io/src.
#pragma once

#include <segmatch/io/error.h>

#include <cstddef>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace segmatch {
namespace io {
namespace detail {

// Throws IoError("<where>: <problem>"). `where` is a path, or "<path> line <n>".
[[noreturn]] void fail(const std::string& where, const std::string& problem);
std::string line_ref(const std::string& path, size_t line_number);

// Whole file in one read (fast, and the parsers then work on memory with bounds checks).
// Missing file => IoError "missing file: <path>".
std::string read_file(const std::string& path);
// At most max_bytes from the start of the file (to peek at a header).
std::string read_file_prefix(const std::string& path, size_t max_bytes);

// Buffered writer that checks every write and the final flush/close, so a full disk or a
// vanished directory surfaces as IoError instead of a silently short file.
class FileWriter {
 public:
  explicit FileWriter(const std::string& path);
  ~FileWriter();
  FileWriter(const FileWriter&) = delete;
  FileWriter& operator=(const FileWriter&) = delete;

  void write(const void* data, size_t size);
  void write(std::string_view text) { write(text.data(), text.size()); }
  void close();  // must be called; throws when the data did not reach the file

 private:
  [[noreturn]] void fail_errno(const char* what, int error);
  std::string path_;
  std::FILE* file_ = nullptr;
};

void write_file(const std::string& path, std::string_view content);

// A printable, shortened copy of untrusted text for error messages.
std::string quote(std::string_view text);

// Text parsing. parse_double accepts what strtod accepts for decimal numbers (leading '+',
// exponents, nan, inf) and requires the whole token to be consumed.
bool parse_double(std::string_view token, double* value);
void split_tokens(std::string_view line, std::vector<std::string_view>* tokens);
std::string_view trim(std::string_view text);
// Splits off the next line (without '\n' and a trailing '\r'); returns false at the end.
bool next_line(std::string_view* text, std::string_view* line);

// Parses exactly `expected` finite numbers into out[0..expected); `where` names the line.
// Wrong count, non-numbers and NaN/Inf raise IoError.
void parse_finite_numbers(const std::string& where, const std::vector<std::string_view>& tokens, size_t expected,
                          double* out);

// Shortest text that reads back to exactly the same value.
void append_number(std::string* out, double value);
void append_number(std::string* out, float value);

// Lowercase file extension including the dot (".pcd"), or "" when there is none.
std::string extension_lower(const std::string& path);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
