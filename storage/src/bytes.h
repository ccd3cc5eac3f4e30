// A read-only view of a BLOB column (or of bytes about to be stored as one).
#pragma once

#include <cstddef>

namespace segmatch {
namespace storage {
namespace detail {

struct BlobView {
  const void* data = nullptr;
  size_t size = 0;
  bool is_null = true;  // SQL NULL (e.g. a segment without ESF), distinct from an empty blob
};

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
