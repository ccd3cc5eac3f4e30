// MCAP writer with the "ros2" profile, as rosbag2's MCAP storage writes it: ros2msg schemas,
// CDR channels, chunks (zstd, lz4 or none) each followed by its MessageIndex records, then a
// summary (schemas, channels, statistics, chunk indexes) that indexed readers jump to.
#include "io_util.h"
#include "mcap.h"

#include <algorithm>
#include <map>

namespace segmatch {
namespace io {

using namespace detail::mcap;

namespace {

struct ChannelState {
  std::string topic;
  uint32_t sequence = 0;
  uint64_t messages = 0;
};

// (log_time, offset in the chunk's records) of one channel's messages in the open chunk.
using ChunkMessageIndex = std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>>;

void put_u16_u64_map(std::string* out, const std::map<uint16_t, uint64_t>& map) {
  detail::mcap::put_u32(out, static_cast<uint32_t>(map.size() * 10));
  for (const auto& [key, value] : map) {
    put_u16(out, key);
    put_u64(out, value);
  }
}

}  // namespace

struct McapWriter::Impl {
  Impl(const std::string& path, const McapWriterOptions& options) : path(path), options(options), file(path) {}

  std::string path;
  McapWriterOptions options;
  detail::FileWriter file;
  uint64_t offset = 0;    // bytes written so far
  uint32_t data_crc = 0;  // CRC-32 of every byte before DataEnd (magic and Header included)
  bool closed = false;

  std::map<std::string, uint16_t> schema_ids;  // by type
  std::map<uint16_t, ChannelState> channels;
  std::string schema_records, channel_records, chunk_index_records;  // repeated in the summary

  std::string chunk;  // the open chunk's uncompressed records
  uint64_t chunk_start = UINT64_MAX, chunk_end = 0;
  ChunkMessageIndex chunk_index;

  uint64_t message_count = 0, message_start = UINT64_MAX, message_end = 0;
  uint32_t chunk_count = 0;

  void emit(uint8_t opcode, std::string_view body) {
    std::string record;
    put_record(&record, opcode, body);
    emit_bytes(record);
  }
  void emit_bytes(std::string_view bytes) {
    file.write(bytes);
    offset += bytes.size();
    data_crc = crc32(data_crc, bytes.data(), bytes.size());  // only used up to DataEnd
  }
  void flush_chunk();
  void write_summary();
};

McapWriter::McapWriter(const std::string& path, const McapWriterOptions& options)
    : impl_(std::make_unique<Impl>(path, options)) {
  impl_->emit_bytes(kMagic);
  std::string header;
  put_string(&header, "ros2");
  put_string(&header, "segmatch");
  impl_->emit(kHeader, header);
}

McapWriter::~McapWriter() {
  if (!impl_->closed) {
    try {
      close();
    } catch (...) {  // a destructor must not throw; call close() to see the error
    }
  }
}

uint16_t McapWriter::add_channel(const std::string& topic, const std::string& type) {
  Impl& w = *impl_;
  if (w.closed) throw IoError(w.path + ": add_channel after close");
  const std::string definition = ros2msg_definition(type);
  if (definition.empty()) throw IoError(w.path + ": no message definition for type '" + type + "'");
  if (w.channels.size() >= 65535) throw IoError(w.path + ": too many channels");
  auto schema = w.schema_ids.find(type);
  if (schema == w.schema_ids.end()) {
    schema = w.schema_ids.emplace(type, static_cast<uint16_t>(w.schema_ids.size() + 1)).first;  // 0: none
    std::string body;
    put_u16(&body, schema->second);
    put_string(&body, type);
    put_string(&body, "ros2msg");
    put_string(&body, definition);
    w.emit(kSchema, body);
    put_record(&w.schema_records, kSchema, body);
  }
  const uint16_t id = static_cast<uint16_t>(w.channels.size() + 1);
  std::string body;
  put_u16(&body, id);
  put_u16(&body, schema->second);
  put_string(&body, topic);
  put_string(&body, "cdr");
  put_u32(&body, 0);  // metadata: an empty map
  w.emit(kChannel, body);
  put_record(&w.channel_records, kChannel, body);
  w.channels[id].topic = topic;
  return id;
}

void McapWriter::write(uint16_t channel, uint64_t log_time_ns, std::string_view cdr) {
  Impl& w = *impl_;
  if (w.closed) throw IoError(w.path + ": write after close");
  const auto it = w.channels.find(channel);
  if (it == w.channels.end()) throw IoError(w.path + ": write to unknown channel " + std::to_string(channel));
  std::string body;
  put_u16(&body, channel);
  put_u32(&body, it->second.sequence++);
  put_u64(&body, log_time_ns);
  put_u64(&body, log_time_ns);  // publish_time: not known apart from the log time
  body.append(cdr.data(), cdr.size());
  ++it->second.messages;
  ++w.message_count;
  w.message_start = std::min(w.message_start, log_time_ns);
  w.message_end = std::max(w.message_end, log_time_ns);
  if (!w.options.chunked) {
    w.emit(kMessage, body);
    return;
  }
  w.chunk_index[channel].emplace_back(log_time_ns, w.chunk.size());
  put_record(&w.chunk, kMessage, body);
  w.chunk_start = std::min(w.chunk_start, log_time_ns);
  w.chunk_end = std::max(w.chunk_end, log_time_ns);
  if (w.chunk.size() >= w.options.chunk_size_bytes) w.flush_chunk();
}

void McapWriter::Impl::flush_chunk() {
  if (chunk.empty()) return;
  const std::string compressed = compress(options.compression, chunk);
  std::string body;
  put_u64(&body, chunk_start);
  put_u64(&body, chunk_end);
  put_u64(&body, chunk.size());
  put_u32(&body, crc32(0, chunk.data(), chunk.size()));
  put_string(&body, compression_name(options.compression));
  put_u64(&body, compressed.size());
  body += compressed;
  const uint64_t chunk_offset = offset;
  emit(kChunk, body);
  const uint64_t chunk_length = offset - chunk_offset;

  // One MessageIndex per channel, entries in log-time order, right after the chunk.
  std::map<uint16_t, uint64_t> index_offsets;
  const uint64_t indexes_start = offset;
  for (auto& [channel, entries] : chunk_index) {
    std::stable_sort(entries.begin(), entries.end(), [](const auto& l, const auto& r) { return l.first < r.first; });
    std::string index;
    put_u16(&index, channel);
    put_u32(&index, static_cast<uint32_t>(entries.size() * 16));
    for (const auto& [time, at] : entries) {
      put_u64(&index, time);
      put_u64(&index, at);
    }
    index_offsets[channel] = offset;
    emit(kMessageIndex, index);
  }
  std::string chunk_index_body;
  put_u64(&chunk_index_body, chunk_start);
  put_u64(&chunk_index_body, chunk_end);
  put_u64(&chunk_index_body, chunk_offset);
  put_u64(&chunk_index_body, chunk_length);
  put_u16_u64_map(&chunk_index_body, index_offsets);
  put_u64(&chunk_index_body, offset - indexes_start);
  put_string(&chunk_index_body, compression_name(options.compression));
  put_u64(&chunk_index_body, compressed.size());
  put_u64(&chunk_index_body, chunk.size());
  put_record(&chunk_index_records, kChunkIndex, chunk_index_body);

  ++chunk_count;
  chunk.clear();
  chunk_index.clear();
  chunk_start = UINT64_MAX;
  chunk_end = 0;
}

// Summary groups, their SummaryOffset records and the footer. The footer's summary_crc covers
// the summary and offsets sections and the footer's first two fields, as the spec defines it.
void McapWriter::Impl::write_summary() {
  std::string stats;
  put_u64(&stats, message_count);
  put_u16(&stats, static_cast<uint16_t>(schema_ids.size()));
  put_u32(&stats, static_cast<uint32_t>(channels.size()));
  put_u32(&stats, 0);  // attachments
  put_u32(&stats, 0);  // metadata
  put_u32(&stats, chunk_count);
  put_u64(&stats, message_count ? message_start : 0);
  put_u64(&stats, message_count ? message_end : 0);
  std::map<uint16_t, uint64_t> counts;
  for (const auto& [id, channel] : channels) counts[id] = channel.messages;
  put_u16_u64_map(&stats, counts);
  std::string statistics_record;
  put_record(&statistics_record, kStatistics, stats);

  const uint64_t summary_start = offset;
  std::string summary, offsets;
  const std::pair<uint8_t, const std::string*> groups[] = {{kSchema, &schema_records},
                                                           {kChannel, &channel_records},
                                                           {kStatistics, &statistics_record},
                                                           {kChunkIndex, &chunk_index_records}};
  for (const auto& [opcode, records] : groups) {
    if (records->empty()) continue;
    std::string body;
    body.push_back(static_cast<char>(opcode));
    put_u64(&body, summary_start + summary.size());
    put_u64(&body, records->size());
    put_record(&offsets, kSummaryOffset, body);
    summary += *records;
  }
  std::string footer;
  put_u64(&footer, summary_start);
  put_u64(&footer, summary_start + summary.size());
  std::string crc_input = summary + offsets;
  crc_input.push_back(static_cast<char>(kFooter));
  put_u64(&crc_input, 20);  // the footer body's length
  crc_input += footer;
  put_u32(&footer, crc32(0, crc_input.data(), crc_input.size()));
  emit_bytes(summary);
  emit_bytes(offsets);
  emit(kFooter, footer);
  emit_bytes(kMagic);
}

void McapWriter::close() {
  Impl& w = *impl_;
  if (w.closed) return;
  w.closed = true;  // even if what follows throws: the file is then unusable anyway
  w.flush_chunk();
  std::string data_end;
  put_u32(&data_end, w.data_crc);
  w.emit(kDataEnd, data_end);
  w.write_summary();
  w.file.close();
}

}  // namespace io
}  // namespace segmatch
