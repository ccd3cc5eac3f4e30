// Malformed MCAP files: each is an IoError naming the file, the record and the byte offset, and
// never a crash or an allocation the file cannot justify.
#include <segmatch/io/bag.h>

#include <random>

#include "bag_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::McapBytes;
using test::ThrowsIoError;

std::string small_recording(const test::TempDir& dir, McapCompression compression, bool chunked = true) {
  const std::string path = dir.file("rec.mcap");
  test::write_recording(path, {chunked, compression, 8000});
  return test::read_bytes(path);
}

// Opens the bytes as a file and reads and decodes every message the way a replay would.
void read_everything(const std::string& path) {
  const std::unique_ptr<BagReader> bag = BagReader::open(path);
  for (const BagTopic& topic : bag->topics()) {
    for (const BagMessageRef& ref : bag->messages(topic.name)) {
      const std::string data = bag->data(ref);
      if (topic.type == "sensor_msgs/msg/PointCloud2") decode_point_cloud2(data);
      if (topic.type == "nav_msgs/msg/Odometry") decode_odometry(data);
      if (topic.type == "tf2_msgs/msg/TFMessage") decode_tf_message(data);
    }
  }
}

const std::string kMagic("\x89MCAP0\r\n", 8);

uint64_t le64(const std::string& b, size_t at) {
  uint64_t v = 0;
  for (size_t i = 0; i < 8; ++i) v |= uint64_t{static_cast<uint8_t>(b[at + i])} << (8 * i);
  return v;
}

TEST(BagErrors, TruncatedFiles) {
  test::TempDir dir;
  const std::string bytes = small_recording(dir, McapCompression::kZstd);
  const std::string path = dir.file("cut.mcap");
  for (size_t cut : {size_t{0}, size_t{5}, size_t{12}}) {
    test::write_bytes(path, bytes.substr(0, cut));
    EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {path, "too short"})) << cut;
  }
  for (size_t cut : {size_t{30}, bytes.size() / 3, bytes.size() / 2, bytes.size() - 30, bytes.size() - 1}) {
    test::write_bytes(path, bytes.substr(0, cut));
    EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {path, "no closing magic", "truncated"})) << cut;
  }
  // Cut inside the data section with the closing magic put back: the scan itself must notice.
  const size_t data_end = bytes.rfind(std::string("\x0f\x04\0\0\0\0\0\0\0", 9));
  for (size_t cut = 8; cut < data_end; cut += 211) {
    test::write_bytes(path, bytes.substr(0, cut) + kMagic);
    EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {path, "offset", "truncated"})) << cut;
  }
}

TEST(BagErrors, WrongMagicAndNotABag) {
  test::TempDir dir;
  std::string bytes = small_recording(dir, McapCompression::kNone);
  bytes[1] = 'X';
  test::write_bytes(dir.file("bad.mcap"), bytes);
  EXPECT_TRUE(
      ThrowsIoError([&] { BagReader::open(dir.file("bad.mcap")); }, {dir.file("bad.mcap"), "wrong magic at offset 0"}));
  test::write_bytes(dir.file("scan.bin"), std::string(64, '\0'));
  EXPECT_FALSE(BagReader::is_bag(dir.file("scan.bin")));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("scan.bin")); }, {"scan.bin", "not a bag"}));
}

std::string header_record() { return McapBytes::record(0x01, McapBytes::str("ros2") + McapBytes::str("")); }

// A file holding one chunk with the given compression string, compressed bytes and sizes.
std::string chunk_file(const std::string& compression, const std::string& records, uint64_t uncompressed,
                       uint32_t crc = 0) {
  return McapBytes().add(header_record()).add(McapBytes::chunk(compression, records, uncompressed, crc)).finish();
}

TEST(BagErrors, ChunksThatCannotBeDecompressed) {
  test::TempDir dir;
  const std::string path = dir.file("c.mcap");
  const std::string inner = McapBytes::channel(1, 0, "/a", "cdr") + McapBytes::message(1, 1, "x");
  test::write_bytes(path, chunk_file("bz2", inner, inner.size()));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); },
                            {path, "Chunk record at offset 29", "compression 'bz2' is not supported"}));
  test::write_bytes(path, chunk_file("zstd", std::string(40, '\x55'), 1000));
  EXPECT_TRUE(
      ThrowsIoError([&] { BagReader::open(path); }, {"Chunk record at offset 29", "zstd decompression failed"}));
  test::write_bytes(path, chunk_file("lz4", std::string(40, '\x55'), 1000));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {"Chunk record at offset 29", "lz4 decompression failed"}));
  // A forged size: 40 bytes cannot expand to 1 TB, and nothing that large is allocated.
  test::write_bytes(path, chunk_file("zstd", std::string(40, '\x55'), 1ull << 40));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {"uncompressed_size 1099511627776", "can expand 40"}));
  test::write_bytes(path, chunk_file("", inner, inner.size(), 12345));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {"Chunk record at offset 29", "CRC mismatch", "12345"}));
  test::write_bytes(path, chunk_file("", inner + "\x05", inner.size() + 1));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); },
                            {"Message record at offset", "in the chunk at offset 29", "runs past the end"}));
}

// A damaged uncompressed_size within what zstd could expand to: the frame's own content size
// disagrees, and that is found before the chunk's buffer is allocated: when the chunk is first
// read (its bag opened from the summary's indexes decompresses nothing).
TEST(BagErrors, UncompressedSizeDisagreeingWithTheZstdFrame) {
  test::TempDir dir;
  std::string bytes = small_recording(dir, McapCompression::kZstd);
  size_t at = 8;
  while (bytes[at] != 0x06) at += 9 + static_cast<size_t>(le64(bytes, at + 1));
  const uint64_t size = le64(bytes, at + 9 + 16);
  bytes.replace(at + 9 + 16, 8, McapBytes::u64(size * 2));
  test::write_bytes(dir.file("d.mcap"), bytes);
  const auto read_all = [&] {
    const std::unique_ptr<BagReader> bag = BagReader::open(dir.file("d.mcap"));
    for (const BagTopic& t : bag->topics())
      for (const BagMessageRef& ref : bag->messages(t.name)) bag->data(ref);
  };
  EXPECT_TRUE(ThrowsIoError(read_all, {"Chunk record at offset " + std::to_string(at),
                                       "the zstd frame holds " + std::to_string(size) +
                                           " bytes, uncompressed_size says " + std::to_string(size * 2)}));
}

TEST(BagErrors, LengthsPastTheEndAndMissingChannels) {
  test::TempDir dir;
  const std::string path = dir.file("l.mcap");
  std::string channel = McapBytes::channel(1, 0, "/a", "cdr");
  channel.replace(1, 8, McapBytes::u64(1ull << 50));
  test::write_bytes(path, McapBytes().add(header_record()).add(channel).finish());
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); },
                            {"Channel record at offset 29", "length 1125899906842624 runs past the end"}));
  // A string length beyond its record.
  std::string topic = McapBytes::channel(1, 0, "/a", "cdr");
  topic.replace(9 + 4, 4, McapBytes::u32(1000));
  test::write_bytes(path, McapBytes().add(header_record()).add(topic).finish());
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); },
                            {"Channel record at offset 29", "field topic: length 1000 at offset 42"}));
  test::write_bytes(path, McapBytes().add(header_record()).add(McapBytes::message(9, 1, "x")).finish());
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); },
                            {"Message record at offset 29", "channel 9 has no Channel record before it"}));
  test::write_bytes(path, McapBytes().add(McapBytes::channel(1, 0, "/a", "cdr")).finish());
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(path); }, {"the first record is not a Header"}));
}

TEST(BagErrors, CorruptedPayloadIsRefusedByTheDecoder) {
  test::TempDir dir;
  const std::string path = dir.file("p.mcap");
  McapWriter writer(path, {false, McapCompression::kNone});
  const uint16_t points = writer.add_channel("/points", "sensor_msgs/msg/PointCloud2");
  std::string cloud = encode_point_cloud2(RosHeader{}, test::random_cloud(10, 1));
  cloud.resize(cloud.size() - 20);  // the data sequence is now shorter than announced
  writer.write(points, 1, cloud);
  writer.close();
  const std::unique_ptr<BagReader> bag = BagReader::open(path);
  EXPECT_TRUE(ThrowsIoError([&] { decode_point_cloud2(bag->data(bag->messages("/points").at(0))); },
                            {"PointCloud2.data: 160 bytes announced at offset", "141 left"}));
  EXPECT_THROW({ McapWriter w(dir.file("no/such/folder/x.mcap")); }, IoError);
  EXPECT_THROW(writer.write(points, 2, cloud), IoError);  // after close
}

// Random damage to valid files of every flavour: whatever happens must be an IoError.
TEST(BagErrors, RandomByteDamageGivesOnlyIoErrors) {
  test::TempDir dir;
  std::mt19937 rng(7);
  const std::string path = dir.file("damaged.mcap");
  for (auto [compression, chunked] : {std::pair{McapCompression::kZstd, true},
                                      {McapCompression::kLz4, true},
                                      {McapCompression::kNone, true},
                                      {McapCompression::kNone, false}}) {
    const std::string bytes = small_recording(dir, compression, chunked);
    for (int trial = 0; trial < 300; ++trial) {
      std::string damaged = bytes;
      const int flips = 1 + int(rng() % 4);
      for (int f = 0; f < flips; ++f) damaged[rng() % damaged.size()] = static_cast<char>(rng());
      test::write_bytes(path, damaged);
      EXPECT_TRUE(test::SucceedsOrThrowsIoError([&] { read_everything(path); })) << trial;
    }
  }
}

// Every message indexed from the summary (no chunk decompressed at open) is the one a scan of
// the data section finds: the same file with its footer's summary_start zeroed, or with a
// Statistics message count the indexes do not reach (as when messages lie outside chunks), is
// scanned and gives the same topics, times and bytes.
TEST(BagErrors, TheSummaryIndexesWhatAScanFinds) {
  test::TempDir dir;
  const std::string bytes = small_recording(dir, McapCompression::kZstd);
  const size_t footer = bytes.size() - 8 - 29;  // closing magic; footer record: 9 + 8 + 8 + 4
  ASSERT_EQ(bytes[footer], '\x02');
  std::string scanned = bytes;
  scanned.replace(footer + 9, 8, McapBytes::u64(0));
  std::string miscounted = bytes;
  size_t statistics = static_cast<size_t>(le64(bytes, footer + 9));  // summary_start
  while (statistics < footer && bytes[statistics] != 0x0B)
    statistics += 9 + static_cast<size_t>(le64(bytes, statistics + 1));
  ASSERT_LT(statistics, footer) << "the writer puts a Statistics record in the summary";
  miscounted.replace(statistics + 9, 8, McapBytes::u64(le64(bytes, statistics + 9) + 1));
  const auto listing = [](const std::string& path) {
    const std::unique_ptr<BagReader> bag = BagReader::open(path);
    std::string out;
    for (const BagTopic& t : bag->topics())
      for (const BagMessageRef& ref : bag->messages(t.name))
        out += t.name + std::to_string(ref.log_time_ns) + bag->data(ref);
    return out;
  };
  test::write_bytes(dir.file("summary.mcap"), bytes);
  test::write_bytes(dir.file("scanned.mcap"), scanned);
  test::write_bytes(dir.file("miscounted.mcap"), miscounted);
  const std::string indexed = listing(dir.file("summary.mcap"));
  EXPECT_GT(indexed.size(), 1000u);
  EXPECT_EQ(indexed, listing(dir.file("scanned.mcap")));
  EXPECT_EQ(indexed, listing(dir.file("miscounted.mcap")));
  // A bag whose chunk is damaged opens from its summary and refuses the damaged read; scanned,
  // it refuses to open.
  std::string damaged = bytes;
  size_t chunk = 8;
  while (damaged[chunk] != 0x06) chunk += 9 + static_cast<size_t>(le64(damaged, chunk + 1));
  damaged[chunk + 9 + 8 + 8 + 8 + 4 + 4 + 4 + 8 + 10] ^= 0x5a;  // inside the compressed records
  test::write_bytes(dir.file("damaged.mcap"), damaged);
  EXPECT_NO_THROW(BagReader::open(dir.file("damaged.mcap")));
  EXPECT_THROW(listing(dir.file("damaged.mcap")), IoError);
}

}  // namespace
}  // namespace io
}  // namespace segmatch
