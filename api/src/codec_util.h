// Shared by the codec's translation units.
#pragma once

#include "segmatch/api/protocol.h"
#include "wire.h"

namespace segmatch {
namespace api {
namespace detail {

// Header + payload as one frame.
std::vector<uint8_t> frame(MessageType type, wire::Writer& payload);
// kOk when the reader consumed exactly its bytes.
DecodeStatus finish(const wire::Reader& r);

}  // namespace detail
}  // namespace api
}  // namespace segmatch
