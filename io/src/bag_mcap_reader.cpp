// MCAP bags. Opening indexes every Message record from the summary section when it accounts for
// all of them (its ChunkIndex records and the MessageIndex records they point to, checked
// against the Statistics record's message count): no chunk is decompressed. Otherwise (no
// summary, messages outside chunks, anything in it that does not parse) one linear scan of the
// data section indexes them, whether they sit in a chunk or not, so a file whose summary is
// missing or damaged still opens. data() then reads one record (decompressing its chunk, the
// last one cached).
#include "bag_internal.h"
#include "mcap.h"

#include <map>
#include <set>

namespace segmatch {
namespace io {
namespace detail {

namespace {

using namespace mcap;

struct Channel {
  std::string topic;
  std::string encoding;
};

uint64_t le64(std::string_view bytes) {
  uint64_t v = 0;
  for (size_t i = 0; i < 8; ++i) v |= uint64_t{static_cast<uint8_t>(bytes[i])} << (8 * i);
  return v;
}

class McapReader final : public IndexedBag {
 public:
  explicit McapReader(const std::string& path) : IndexedBag(path), file_(path) {
    check_magic();
    if (!from_summary()) {
      schema_names_.clear(), channels_.clear(), topics_.clear(), messages_.clear();
      crc_at_read_ = false;
      scan();
    }
    for (BagTopic& topic : topics_) {
      std::vector<BagMessageRef>& refs = messages_[topic.name];
      sort_by_log_time(&refs);
      topic.messages = refs.size();
    }
  }

  std::string data(const BagMessageRef& ref) const override;

 private:
  std::string where(uint8_t opcode, uint64_t offset) const {
    return path_ + ": " + opcode_name(opcode) + " record at offset " + std::to_string(offset);
  }
  std::string where_in_chunk(uint8_t opcode, uint64_t offset, uint64_t chunk) const {
    return where(opcode, offset) + " in the chunk at offset " + std::to_string(chunk);
  }
  void check_magic() const;
  bool from_summary();
  bool index_chunk_messages(uint64_t chunk, uint64_t message_index_at, uint64_t* found);
  void scan();
  void scan_chunk(uint64_t chunk, std::string_view body);
  void index(uint8_t opcode, std::string_view body, uint64_t base, const std::string& where, BagMessageRef ref);
  // The chunk's records, decompressed; their CRC checked when check_crc (opening checks every
  // chunk once: data() does not again).
  std::string chunk_records(std::string_view body, uint64_t chunk, bool check_crc = true) const;
  const std::string& cached_chunk(uint64_t chunk) const;
  std::string payload(std::string_view body, uint64_t base, const std::string& where) const;

  RandomAccessFile file_;
  std::map<uint16_t, std::string> schema_names_;
  std::map<uint16_t, Channel> channels_;
  // topics_ in the order their first channel appears.
  // Not thread-safe: data() keeps the last decompressed chunk, so reading a topic in order
  // decompresses each chunk once.
  bool crc_at_read_ = false;  // indexed from the summary: data() checks a chunk's CRC, once
  mutable std::set<uint64_t> crc_checked_;
  mutable uint64_t cached_offset_ = UINT64_MAX;
  mutable std::string cached_records_;
};

void McapReader::check_magic() const {
  const uint64_t size = file_.size();
  if (size < 2 * kMagic.size()) {
    throw IoError(path_ + ": " + std::to_string(size) + " bytes, too short for an MCAP file (" +
                  (size == 0 ? "empty" : "truncated or wrong magic") + ")");
  }
  if (file_.read(0, kMagic.size(), path_) != kMagic) {
    throw IoError(path_ + ": wrong magic at offset 0: not an MCAP file");
  }
  if (file_.read(size - kMagic.size(), kMagic.size(), path_) != kMagic) {
    throw IoError(path_ + ": no closing magic at offset " + std::to_string(size - kMagic.size()) +
                  ": the file is truncated (a recording that was not closed?)");
  }
}

bool McapReader::from_summary() try {
  constexpr uint64_t kFooterBody = 8 + 8 + 4;  // summary_start, summary_offset_start, summary_crc
  const uint64_t size = file_.size();
  if (size < 2 * kMagic.size() + kRecordPrefix + kFooterBody) return false;
  const uint64_t footer_at = size - kMagic.size() - kRecordPrefix - kFooterBody;
  const std::string footer = file_.read(footer_at, kRecordPrefix + kFooterBody, path_);
  if (static_cast<uint8_t>(footer[0]) != kFooter || le64(std::string_view(footer).substr(1)) != kFooterBody)
    return false;
  FieldReader f(std::string_view(footer).substr(kRecordPrefix), footer_at + kRecordPrefix, where(kFooter, footer_at));
  const uint64_t start = f.u64("summary_start"), offsets = f.u64("summary_offset_start");
  const uint64_t end = offsets != 0 ? offsets : footer_at;
  if (start < kMagic.size() || start >= end || end > footer_at) return false;
  const std::string summary = file_.read(start, end - start, where(kFooter, footer_at));
  uint64_t expected = UINT64_MAX, found = 0;
  std::vector<std::pair<uint64_t, uint64_t>> indexes;  // (chunk, its MessageIndex record)
  for (size_t pos = 0; pos < summary.size();) {
    if (summary.size() - pos < kRecordPrefix) return false;
    const uint8_t opcode = static_cast<uint8_t>(summary[pos]);
    const uint64_t length = le64(std::string_view(summary).substr(pos + 1));
    if (length > summary.size() - pos - kRecordPrefix) return false;
    const std::string_view body = std::string_view(summary).substr(pos + kRecordPrefix, length);
    const uint64_t at = start + pos;
    FieldReader r(body, at + kRecordPrefix, where(opcode, at));
    if (opcode == kSchema || opcode == kChannel) {
      index(opcode, body, at + kRecordPrefix, where(opcode, at), {});
    } else if (opcode == kStatistics) {
      expected = r.u64("message_count");
    } else if (opcode == kChunkIndex) {
      r.u64("message_start_time"), r.u64("message_end_time");
      const uint64_t chunk = r.u64("chunk_start_offset");
      r.u64("chunk_length");
      const std::string_view map = r.bytes("message_index_offsets", r.u32("message_index_offsets length"));
      for (size_t k = 0; k + 10 <= map.size(); k += 10) indexes.emplace_back(chunk, le64(map.substr(k + 2)));
    }
    pos += kRecordPrefix + length;
  }
  if (expected == UINT64_MAX) return false;
  for (const auto& [chunk, message_index] : indexes)
    if (!index_chunk_messages(chunk, message_index, &found)) return false;
  crc_at_read_ = true;
  return found == expected;  // fewer: some messages lie outside chunks, which only a scan finds
} catch (const IoError&) {
  return false;  // a damaged summary: the scan decides
}

// One MessageIndex record: a chunk's messages on one channel, (log time, offset of the Message
// record in the chunk's decompressed records), indexed as scan_chunk() indexes them.
bool McapReader::index_chunk_messages(uint64_t chunk, uint64_t message_index, uint64_t* found) {
  const std::string at = where(kMessageIndex, message_index);
  const std::string prefix = file_.read(message_index, kRecordPrefix, at);
  if (static_cast<uint8_t>(prefix[0]) != kMessageIndex) return false;
  const std::string body = file_.read(message_index + kRecordPrefix, le64(std::string_view(prefix).substr(1)), at);
  FieldReader r(body, message_index + kRecordPrefix, at);
  const auto channel = channels_.find(r.u16("channel_id"));
  if (channel == channels_.end()) return false;
  const std::string_view entries = r.bytes("records", r.u32("records length"));
  std::vector<BagMessageRef>& refs = messages_[channel->second.topic];
  for (size_t k = 0; k + 16 <= entries.size(); k += 16, ++*found)
    refs.push_back(BagMessageRef{le64(entries.substr(k)), chunk, le64(entries.substr(k + 8)) + 1, 0, {}});
  return true;
}

void McapReader::scan() {
  const uint64_t end = file_.size() - kMagic.size();  // where the closing magic starts
  uint64_t pos = kMagic.size();
  for (bool first = true;; first = false) {
    if (end - pos < kRecordPrefix) {
      throw IoError(path_ + ": truncated: the record at offset " + std::to_string(pos) + " has " +
                    std::to_string(end - pos) + " of its 9 header bytes before the closing magic" +
                    (end == pos ? " (no DataEnd or Footer record)" : ""));
    }
    const std::string prefix = file_.read(pos, kRecordPrefix, path_);
    const uint8_t opcode = static_cast<uint8_t>(prefix[0]);
    const uint64_t length = le64(std::string_view(prefix).substr(1));
    const uint64_t left = end - pos - kRecordPrefix;
    if (length > left) {
      throw IoError(where(opcode, pos) + ": length " + std::to_string(length) + " runs past the end of the file (" +
                    std::to_string(left) + " bytes left before the closing magic): truncated?");
    }
    if (first && opcode != kHeader) {
      throw IoError(where(opcode, pos) + ": the first record is not a Header: not an MCAP file");
    }
    if (opcode == kDataEnd || opcode == kFooter) return;  // the summary repeats what we indexed
    const uint64_t body_at = pos + kRecordPrefix;
    if (opcode == kChunk) {
      scan_chunk(pos, file_.read(body_at, length, where(opcode, pos)));
    } else if (opcode == kMessage) {  // only the fixed fields: the payload is read by data()
      const std::string head =
          file_.read(body_at, std::min<uint64_t>(length, kMessagePrefix + kBagHeadBytes), where(opcode, pos));
      index(opcode, head, body_at, where(opcode, pos), BagMessageRef{0, pos, 0, 0, {}});
    } else if (opcode == kSchema || opcode == kChannel) {
      index(opcode, file_.read(body_at, length, where(opcode, pos)), body_at, where(opcode, pos), {});
    }
    pos = body_at + length;  // any other record, known or not, is skipped by its length
  }
}

std::string McapReader::chunk_records(std::string_view body, uint64_t chunk, bool check_crc) const {
  const std::string at = where(kChunk, chunk);
  FieldReader f(body, chunk + kRecordPrefix, at);
  f.u64("message_start_time");
  f.u64("message_end_time");
  const uint64_t uncompressed_size = f.u64("uncompressed_size");
  const uint32_t crc = f.u32("uncompressed_crc");
  const std::string_view compression = f.string("compression");
  const size_t length_at = f.position();
  const std::string_view records = f.bytes_at("records", f.u64("records length"), length_at);
  return decompress(compression, records, uncompressed_size, check_crc ? crc : 0, at);
}

void McapReader::scan_chunk(uint64_t chunk, std::string_view body) {
  const std::string records = chunk_records(body, chunk);
  size_t pos = 0;
  while (pos < records.size()) {
    const size_t left = records.size() - pos;
    const uint8_t opcode = static_cast<uint8_t>(records[pos]);
    const uint64_t length = left < kRecordPrefix ? 0 : le64(std::string_view(records).substr(pos + 1));
    if (left < kRecordPrefix || length > left - kRecordPrefix) {
      throw IoError(where_in_chunk(opcode, pos, chunk) + ": " +
                    (left < kRecordPrefix ? "record header" : "length " + std::to_string(length)) +
                    " runs past the end of the chunk's " + std::to_string(records.size()) + " bytes");
    }
    const std::string_view inner = std::string_view(records).substr(pos + kRecordPrefix, length);
    index(opcode, inner, pos + kRecordPrefix, where_in_chunk(opcode, pos, chunk),
          BagMessageRef{0, chunk, pos + 1, 0, {}});
    pos += kRecordPrefix + length;
  }
}

// Schema, Channel and Message records update the index; every other record is ignored.
void McapReader::index(uint8_t opcode, std::string_view body, uint64_t base, const std::string& where,
                       BagMessageRef ref) {
  FieldReader f(body, base, where);
  if (opcode == kSchema) {
    const uint16_t id = f.u16("id");
    const std::string_view name = f.string("name");
    f.string("encoding");
    f.string("data");
    schema_names_.emplace(id, std::string(name));
  } else if (opcode == kChannel) {
    const uint16_t id = f.u16("id");
    const uint16_t schema = f.u16("schema_id");
    const std::string topic(f.string("topic"));
    const std::string encoding(f.string("message_encoding"));
    f.string("metadata");  // a map: its uint32 byte length, then the entries
    if (!channels_.emplace(id, Channel{topic, encoding}).second) return;  // repeated: seen
    const auto known = std::find_if(topics_.begin(), topics_.end(), [&](const BagTopic& t) { return t.name == topic; });
    const auto type = schema_names_.find(schema);  // schema 0: none
    if (known == topics_.end()) topics_.push_back({topic, type == schema_names_.end() ? "" : type->second, 0});
  } else if (opcode == kMessage) {
    const uint16_t channel = f.u16("channel_id");
    f.u32("sequence");
    ref.log_time_ns = f.u64("log_time");
    f.u64("publish_time");
    ref.head = std::string(body.substr(std::min(body.size(), kMessagePrefix), kBagHeadBytes));
    const auto it = channels_.find(channel);
    if (it == channels_.end()) {
      f.fail("channel " + std::to_string(channel) + " has no Channel record before it");
    }
    messages_[it->second.topic].push_back(ref);
  }
}

const std::string& McapReader::cached_chunk(uint64_t chunk) const {
  if (cached_offset_ == chunk) return cached_records_;
  cached_offset_ = UINT64_MAX;  // stays invalid if decompression throws
  const std::string prefix = file_.read(chunk, kRecordPrefix, where(kChunk, chunk));
  if (static_cast<uint8_t>(prefix[0]) != kChunk) {
    throw IoError(where(kChunk, chunk) + ": no Chunk record there (a reference from another bag?)");
  }
  const std::string body =
      file_.read(chunk + kRecordPrefix, le64(std::string_view(prefix).substr(1)), where(kChunk, chunk));
  cached_records_ = chunk_records(body, chunk, crc_at_read_ && !crc_checked_.count(chunk));
  if (crc_at_read_) crc_checked_.insert(chunk);
  cached_offset_ = chunk;
  return cached_records_;
}

std::string McapReader::payload(std::string_view body, uint64_t base, const std::string& where) const {
  FieldReader f(body, base, where);
  const uint16_t channel = f.u16("channel_id");
  f.u32("sequence");
  f.u64("log_time");
  f.u64("publish_time");
  const auto it = channels_.find(channel);
  if (it == channels_.end()) f.fail("unknown channel " + std::to_string(channel));
  if (it->second.encoding != "cdr") {
    f.fail("topic " + it->second.topic + " has message encoding '" + it->second.encoding +
           "': only cdr messages are read");
  }
  return std::string(f.rest());
}

std::string McapReader::data(const BagMessageRef& ref) const {
  if (ref.b == 0) {  // a Message record outside any chunk
    const std::string at = where(kMessage, ref.a);
    const std::string prefix = file_.read(ref.a, kRecordPrefix, at);
    if (static_cast<uint8_t>(prefix[0]) != kMessage) throw IoError(at + ": no Message record there");
    const std::string body = file_.read(ref.a + kRecordPrefix, le64(std::string_view(prefix).substr(1)), at);
    return payload(body, ref.a + kRecordPrefix, at);
  }
  const std::string& records = cached_chunk(ref.a);
  const uint64_t pos = ref.b - 1;
  const std::string at = where_in_chunk(kMessage, pos, ref.a);
  if (pos > records.size() || records.size() - pos < kRecordPrefix || static_cast<uint8_t>(records[pos]) != kMessage) {
    throw IoError(at + ": no Message record there");
  }
  const uint64_t length = le64(std::string_view(records).substr(pos + 1));
  if (length > records.size() - pos - kRecordPrefix) throw IoError(at + ": length runs past the chunk");
  return payload(std::string_view(records).substr(pos + kRecordPrefix, length), pos + kRecordPrefix, at);
}

}  // namespace

std::unique_ptr<BagReader> open_mcap_file(const std::string& path) { return std::make_unique<McapReader>(path); }

}  // namespace detail
}  // namespace io
}  // namespace segmatch
