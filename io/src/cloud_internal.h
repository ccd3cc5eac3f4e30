// Internal entry points shared between the cloud readers and Sequence.
#pragma once

#include <segmatch/io/cloud_io.h>

#include <string>

namespace segmatch {
namespace io {
namespace detail {

// A KITTI scan with its SemanticKITTI labels, dropping non-finite points together with their
// labels (which is why it cannot be done by calling the two public readers separately).
CloudData read_kitti_bin_labeled(const std::string& bin_path, const std::string& label_path);

// True when the PCD header of `path` declares a field with that name (reads only the header).
bool pcd_has_field(const std::string& path, const std::string& field);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
