// Internal: the storage backends behind BagReader::open, and what they share.
#pragma once

#include <segmatch/io/bag.h>

#include <algorithm>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace segmatch {
namespace io {
namespace detail {

std::unique_ptr<BagReader> open_mcap_file(const std::string& path);
std::unique_ptr<BagReader> open_db3_file(const std::string& path);

// What the single-file readers (MCAP, .db3) share: their path, topics and per-topic message
// index, filled when they open.
class IndexedBag : public BagReader {
 public:
  const std::string& path() const override { return path_; }
  const std::vector<BagTopic>& topics() const override { return topics_; }
  std::vector<BagMessageRef> messages(const std::string& topic) const override {
    const auto it = messages_.find(topic);
    return it == messages_.end() ? std::vector<BagMessageRef>{} : it->second;
  }

 protected:
  explicit IndexedBag(std::string path) : path_(std::move(path)) {}
  std::string path_;
  std::vector<BagTopic> topics_;
  std::map<std::string, std::vector<BagMessageRef>> messages_;
};

// The reference's `c` names the file of a rosbag2 folder the message lives in; a single-file
// reader leaves it 0 and ignores it.
inline void sort_by_log_time(std::vector<BagMessageRef>* refs) {
  std::stable_sort(refs->begin(), refs->end(),
                   [](const BagMessageRef& l, const BagMessageRef& r) { return l.log_time_ns < r.log_time_ns; });
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
