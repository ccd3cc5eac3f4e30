// Internal: LZF (liblzf) compression, the codec of PCD "binary_compressed" data.
//
// Written here rather than linked so the io library has no third-party dependency; the
// stream format is liblzf's, so files interoperate with PCL.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace io {
namespace detail {

// Compresses `size` bytes. Any input is accepted (incompressible data grows by 1/32).
std::vector<uint8_t> lzf_compress(const uint8_t* data, size_t size);

// Decompresses into exactly `out_size` bytes. Returns an empty string on success, otherwise
// a description of what is wrong with the stream (corrupt data never reads out of bounds).
std::string lzf_decompress(const uint8_t* in, size_t in_size, uint8_t* out, size_t out_size);

}  // namespace detail
}  // namespace io
}  // namespace segmatch
