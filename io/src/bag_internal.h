// Internal: the storage backends behind BagReader::open, and what they share.
#pragma once

#include <segmatch/io/bag.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

namespace segmatch {
namespace io {
namespace detail {

std::unique_ptr<BagReader> open_mcap_file(const std::string& path);
std::unique_ptr<BagReader> open_db3_file(const std::string& path);

// The reference's `c` names the file of a rosbag2 folder the message lives in; a single-file
// reader leaves it 0 and ignores it.
inline void sort_by_log_time(std::vector<BagMessageRef>* refs) {
  std::stable_sort(refs->begin(), refs->end(), [](const BagMessageRef& l, const BagMessageRef& r) {
    return l.log_time_ns < r.log_time_ns;
  });
}

}  // namespace detail
}  // namespace io
}  // namespace segmatch
