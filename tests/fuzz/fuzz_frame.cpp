// libFuzzer target: an SGMQ frame (docs/protocol.md). The header is decoded, then the payload by
// every message decoder (not only the header's type: each decoder sees every byte sequence). A
// payload that decodes must re-encode to a frame of the same size that decodes again: the server
// never refuses its own replies, nor a client its own requests. (Byte equality holds for the
// golden frames, not for any input: a pose passes through a rotation matrix, so a quaternion read
// from arbitrary bytes may come back an ulp away.) Decoders never throw: an exception is a finding.
#include <segmatch/api/protocol.h>

#include <cstdint>
#include <cstdlib>
#include <vector>

namespace {

using namespace segmatch::api;

template <typename M>
void decode_and_round_trip(const uint8_t* payload, size_t size, const Limits& limits) {
  M message;
  if (decode(payload, size, limits, message) != DecodeStatus::kOk) return;
  const std::vector<uint8_t> frame = encode(message);
  M again;
  if (decode_frame(frame, limits, again) != DecodeStatus::kOk) std::abort();  // encoded, yet refused
  if (encode(again).size() != frame.size()) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Limits limits;
  limits.max_payload_bytes = 1u << 20;  // the fuzzer's inputs are smaller; keeps allocations small
  limits.max_string_bytes = 1u << 16;
  Header header;
  (void)decode_header(data, size, limits, header);
  const uint8_t* payload = size > kHeaderBytes ? data + kHeaderBytes : data;
  const size_t payload_size = size > kHeaderBytes ? size - kHeaderBytes : size;
  decode_and_round_trip<HelloRequest>(payload, payload_size, limits);
  decode_and_round_trip<HelloOkReply>(payload, payload_size, limits);
  decode_and_round_trip<PingRequest>(payload, payload_size, limits);
  decode_and_round_trip<PongReply>(payload, payload_size, limits);
  decode_and_round_trip<InfoRequest>(payload, payload_size, limits);
  decode_and_round_trip<InfoReply>(payload, payload_size, limits);
  decode_and_round_trip<LocalizeRequest>(payload, payload_size, limits);
  decode_and_round_trip<LocalizeSegmentsRequest>(payload, payload_size, limits);
  decode_and_round_trip<LocalizeReply>(payload, payload_size, limits);
  decode_and_round_trip<ErrorReply>(payload, payload_size, limits);
  return 0;
}
