// BagReader::open: an .mcap or .db3 file, or a rosbag2 folder whose metadata.yaml lists the
// files of the recording (split by size or duration) in order; a folder's files are merged as
// one bag.
#include "bag_internal.h"
#include "io_util.h"
#include "mcap.h"

#include <filesystem>

namespace segmatch {
namespace io {

namespace fs = std::filesystem;

namespace {

struct BagMetadata {
  std::string storage_identifier;  // "sqlite3" or "mcap"
  std::string compression_format;  // non-empty: rosbag2 compressed the files or messages
  std::vector<std::string> relative_file_paths;
};

std::string unquote(std::string_view value) {
  value = detail::trim(value);
  if (value.size() >= 2 && (value.front() == '"' || value.front() == '\'') && value.back() == value.front()) {
    value = value.substr(1, value.size() - 2);
  }
  return std::string(value);
}

// The few keys we need from rosbag2's metadata.yaml, read line by line: the file is machine-
// written with one key per line, and relative_file_paths is a block list ("- name" lines) or,
// when hand-edited, a flow list ("[a, b]").
BagMetadata parse_metadata(const std::string& text) {
  BagMetadata out;
  std::string_view rest = text, line;
  bool in_paths = false;
  while (detail::next_line(&rest, &line)) {
    const std::string_view t = detail::trim(line);
    if (t.empty() || t.front() == '#') continue;
    if (in_paths && t.front() == '-') {
      out.relative_file_paths.push_back(unquote(t.substr(1)));
      continue;
    }
    in_paths = false;
    const size_t colon = t.find(':');
    if (colon == std::string_view::npos) continue;
    const std::string_view key = t.substr(0, colon), value = detail::trim(t.substr(colon + 1));
    if (key == "storage_identifier") out.storage_identifier = unquote(value);
    if (key == "compression_format") out.compression_format = unquote(value);
    if (key != "relative_file_paths") continue;
    in_paths = value.empty();
    if (value.size() >= 2 && value.front() == '[' && value.back() == ']') {
      std::string_view items = value.substr(1, value.size() - 2);
      while (!detail::trim(items).empty()) {
        const size_t comma = items.find(',');
        out.relative_file_paths.push_back(unquote(items.substr(0, comma)));
        items = comma == std::string_view::npos ? std::string_view() : items.substr(comma + 1);
      }
    }
  }
  return out;
}

std::unique_ptr<BagReader> open_file(const std::string& path, const std::string& storage = "") {
  const std::string ext = detail::extension_lower(path);
  if (storage == "mcap" || (storage.empty() && ext == ".mcap")) return detail::open_mcap_file(path);
  if (storage == "sqlite3" || (storage.empty() && ext == ".db3")) return detail::open_db3_file(path);
  if (!storage.empty()) throw IoError(path + ": storage '" + storage + "' is not supported (mcap or sqlite3)");
  // Another extension: the first bytes say what it is.
  const std::string head = detail::read_file_prefix(path, 16);
  if (head.compare(0, detail::mcap::kMagic.size(), detail::mcap::kMagic) == 0) return detail::open_mcap_file(path);
  if (head == std::string("SQLite format 3\0", 16)) return detail::open_db3_file(path);
  throw IoError(path + ": not a bag (expected an .mcap or .db3 file, or a rosbag2 folder with metadata.yaml)");
}

// The files of a rosbag2 folder as one bag: topics merged by name, each topic's messages from
// all files in log-time order (ties: file order). A reference's `c` is the file's index.
class FolderReader final : public BagReader {
 public:
  explicit FolderReader(const std::string& folder);

  const std::string& path() const override { return path_; }
  const std::vector<BagTopic>& topics() const override { return topics_; }
  std::vector<BagMessageRef> messages(const std::string& topic) const override {
    std::vector<BagMessageRef> out;
    for (size_t i = 0; i < files_.size(); ++i) {
      for (BagMessageRef ref : files_[i]->messages(topic)) {
        ref.c = i;
        out.push_back(ref);
      }
    }
    detail::sort_by_log_time(&out);
    return out;
  }
  std::string data(const BagMessageRef& ref) const override {
    if (ref.c >= files_.size()) {
      throw IoError(path_ + ": message reference names file " + std::to_string(ref.c) + " of " +
                    std::to_string(files_.size()));
    }
    BagMessageRef inner = ref;
    inner.c = 0;
    return files_[ref.c]->data(inner);
  }

 private:
  std::string path_;
  std::vector<std::unique_ptr<BagReader>> files_;
  std::vector<BagTopic> topics_;
};

FolderReader::FolderReader(const std::string& folder) : path_(folder) {
  const std::string yaml = (fs::path(folder) / "metadata.yaml").string();
  const BagMetadata metadata = parse_metadata(detail::read_file(yaml));
  if (!metadata.compression_format.empty()) {
    throw IoError(yaml + ": compression_format '" + metadata.compression_format +
                  "': compressed rosbag2 bags are not supported (`ros2 bag convert` can write an "
                  "uncompressed copy)");
  }
  if (metadata.relative_file_paths.empty()) throw IoError(yaml + ": relative_file_paths lists no file");
  for (const std::string& relative : metadata.relative_file_paths) {
    fs::path file = fs::path(folder) / relative;
    // Early rosbag2 releases wrote the paths with the bag folder's name in front.
    std::error_code ec;
    if (!fs::exists(file, ec) && fs::exists(fs::path(folder) / fs::path(relative).filename(), ec)) {
      file = fs::path(folder) / fs::path(relative).filename();
    }
    if (!fs::exists(file, ec)) throw IoError(yaml + ": relative_file_paths lists " + relative + ", missing");
    files_.push_back(open_file(file.string(), metadata.storage_identifier));
    for (const BagTopic& topic : files_.back()->topics()) {
      const auto known =
          std::find_if(topics_.begin(), topics_.end(), [&](const BagTopic& t) { return t.name == topic.name; });
      if (known == topics_.end()) {
        topics_.push_back(topic);
      } else {
        known->messages += topic.messages;
      }
    }
  }
}

bool has_metadata(const fs::path& folder) {
  std::error_code ec;
  return fs::is_regular_file(folder / "metadata.yaml", ec);
}

}  // namespace

std::unique_ptr<BagReader> BagReader::open(const std::string& path) {
  std::error_code ec;
  const fs::path p(path);
  if (!fs::exists(p, ec)) throw IoError("missing file: " + path);
  if (fs::is_directory(p, ec)) {
    if (!has_metadata(p)) throw IoError(path + ": a folder without metadata.yaml is not a rosbag2 bag");
    return std::make_unique<FolderReader>(path);
  }
  if (p.filename() == "metadata.yaml") return std::make_unique<FolderReader>(p.parent_path().string());
  return open_file(path);
}

bool BagReader::is_bag(const std::string& path) {
  std::error_code ec;
  const fs::path p(path);
  if (fs::is_directory(p, ec)) return has_metadata(p);
  const std::string ext = detail::extension_lower(path);
  return (ext == ".mcap" || ext == ".db3") && fs::is_regular_file(p, ec);
}

}  // namespace io
}  // namespace segmatch
