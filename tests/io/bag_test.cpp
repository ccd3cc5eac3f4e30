// ROS 2 bags without ROS: McapWriter -> BagReader round trips (zstd, lz4, uncompressed chunks,
// no chunks), the written file's summary, rosbag2 SQLite bags built here as rosbag2 writes them,
// rosbag2 folders (metadata.yaml), and the malformed files each must refuse with IoError.
#include <segmatch/io/bag.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <tuple>

#include "bag_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::McapBytes;
using test::ThrowsIoError;

using test::kT0;
using test::write_recording;

void check_recording(const BagReader& bag) {
  ASSERT_EQ(bag.topics().size(), 3u);
  EXPECT_EQ(bag.topics()[0].name, "/points");
  EXPECT_EQ(bag.topics()[0].type, "sensor_msgs/msg/PointCloud2");
  EXPECT_EQ(bag.topics()[0].messages, 5u);
  EXPECT_EQ(bag.topics()[1].type, "nav_msgs/msg/Odometry");
  EXPECT_EQ(bag.topics()[1].messages, 10u);
  EXPECT_EQ(bag.topics()[2].type, "tf2_msgs/msg/TFMessage");
  const std::vector<BagMessageRef> odom = bag.messages("/odom");
  ASSERT_EQ(odom.size(), 10u);
  for (int k = 0; k < 10; ++k) {
    EXPECT_EQ(odom[k].log_time_ns, kT0 + uint64_t(k) * 50000000);
    const StampedPose pose = decode_odometry(bag.data(odom[k]));
    EXPECT_EQ(pose.header.stamp_sec, k);
    EXPECT_NEAR(pose.T_parent_child.translation().x(), k, 1e-12);
  }
  const std::vector<BagMessageRef> clouds = bag.messages("/points");
  ASSERT_EQ(clouds.size(), 5u);
  for (int k = 4; k >= 0; --k) {  // backwards: each read may need another chunk
    const PointCloud2Message m = decode_point_cloud2(bag.data(clouds[k]));
    EXPECT_EQ(m.header.stamp_sec, k);
    EXPECT_TRUE(test::same_points(m.cloud.points, test::random_cloud(200, 2 * k)));
  }
  const std::vector<BagMessageRef> tf = bag.messages("/tf");
  ASSERT_EQ(tf.size(), 5u);
  EXPECT_EQ(decode_tf_message(bag.data(tf[4])).size(), 2u);
  EXPECT_TRUE(bag.messages("/nothing").empty());
}

struct WriterCase {
  const char* name;
  McapWriterOptions options;
};

class McapRoundTrip : public ::testing::TestWithParam<WriterCase> {};

TEST_P(McapRoundTrip, EveryMessageReadsBack) {
  test::TempDir dir;
  write_recording(dir.file("drive.mcap"), GetParam().options);
  EXPECT_TRUE(BagReader::is_bag(dir.file("drive.mcap")));
  const std::unique_ptr<BagReader> bag = BagReader::open(dir.file("drive.mcap"));
  EXPECT_EQ(bag->path(), dir.file("drive.mcap"));
  check_recording(*bag);
}

uint64_t le(const std::string& b, size_t at, size_t n) {
  uint64_t v = 0;
  for (size_t i = 0; i < n; ++i) v |= uint64_t{static_cast<uint8_t>(b[at + i])} << (8 * i);
  return v;
}

// The summary an indexed reader jumps to: footer -> summary offsets -> groups of the right
// records, chunk indexes pointing at chunks, DataEnd just before the summary.
TEST_P(McapRoundTrip, SummaryPointsAtTheRightRecords) {
  test::TempDir dir;
  write_recording(dir.file("drive.mcap"), GetParam().options);
  const std::string b = test::read_bytes(dir.file("drive.mcap"));
  const size_t footer = b.size() - 8 - 29;
  ASSERT_EQ(b[footer], 0x02);
  const uint64_t summary = le(b, footer + 9, 8), offsets = le(b, footer + 17, 8);
  EXPECT_EQ(b[summary - 13], 0x0F);  // DataEnd
  std::map<int, int> groups;
  for (size_t at = offsets; at < footer; at += 9 + le(b, at + 1, 8)) {
    ASSERT_EQ(b[at], 0x0E);
    const int opcode = b[at + 9];
    const uint64_t start = le(b, at + 10, 8), length = le(b, at + 18, 8);
    for (size_t r = start; r < start + length; r += 9 + le(b, r + 1, 8)) {
      ASSERT_EQ(b[r], opcode);
      ++groups[opcode];
      if (opcode == 0x08) {
        EXPECT_EQ(b[le(b, r + 9 + 16, 8)], 0x06);  // chunk_start_offset
      }
      if (opcode == 0x0B) {
        EXPECT_EQ(le(b, r + 9, 8), 20u);  // message_count
      }
    }
  }
  EXPECT_EQ(groups[0x03], 3);
  EXPECT_EQ(groups[0x04], 3);
  EXPECT_EQ(groups[0x0B], 1);
  EXPECT_EQ(groups[0x08] > 1, GetParam().options.chunked);
}

INSTANTIATE_TEST_SUITE_P(Bag, McapRoundTrip,  // "Bag/": the Bag* filter runs them with the other bag tests
                         ::testing::Values(WriterCase{"Zstd", {true, McapCompression::kZstd, 8000}},
                                           WriterCase{"Lz4", {true, McapCompression::kLz4, 8000}},
                                           WriterCase{"UncompressedChunks", {true, McapCompression::kNone, 8000}},
                                           WriterCase{"Unchunked", {false, McapCompression::kNone, 8000}}),
                         [](const ::testing::TestParamInfo<WriterCase>& info) { return std::string(info.param.name); });

TEST(BagMcap, SchemaCarriesTheDependentDefinitions) {
  test::TempDir dir;
  write_recording(dir.file("drive.mcap"), {});
  const std::string b = test::read_bytes(dir.file("drive.mcap"));
  EXPECT_NE(b.find("ros2msg"), std::string::npos);
  EXPECT_NE(b.find("std_msgs/Header header\nuint32 height"), std::string::npos);
  EXPECT_NE(b.find("================================================================================\n"
                   "MSG: sensor_msgs/PointField\n"),
            std::string::npos);
  EXPECT_NE(b.find("MSG: geometry_msgs/TransformStamped\n"), std::string::npos);
  EXPECT_NE(b.find(McapBytes::str("ros2") + McapBytes::str("segmatch")), std::string::npos);
}

// A file no writer of ours makes: unknown opcodes and a Metadata record to skip, a JSON
// channel (listed, refused when read), an unchunked CDR message.
TEST(BagMcap, UnknownRecordsAreSkippedAndNonCdrTopicsRefusedByName) {
  test::TempDir dir;
  test::Cdr pose;
  pose.header(7, 0, "map").put(1.0).put(2.0).put(3.0).put(0.0).put(0.0).put(0.0).put(1.0);
  const std::string bytes = McapBytes()
                                .add(McapBytes::record(0x01, McapBytes::str("ros2") + McapBytes::str("x")))
                                .add(McapBytes::record(0x80, "opaque"))
                                .add(McapBytes::channel(1, 0, "/pose", "cdr"))
                                .add(McapBytes::channel(2, 0, "/json", "json"))
                                .add(McapBytes::record(0x0C, McapBytes::str("m") + McapBytes::u32(0)))
                                .add(McapBytes::message(2, 5, "{}"))
                                .add(McapBytes::message(1, 6, pose.bytes()))
                                .finish();
  test::write_bytes(dir.file("hand.mcap"), bytes);
  const std::unique_ptr<BagReader> bag = BagReader::open(dir.file("hand.mcap"));
  ASSERT_EQ(bag->topics().size(), 2u);
  EXPECT_EQ(bag->topics()[1].name, "/json");
  EXPECT_EQ(bag->topics()[1].messages, 1u);
  EXPECT_EQ(decode_pose_stamped(bag->data(bag->messages("/pose").at(0))).header.stamp_sec, 7);
  EXPECT_TRUE(ThrowsIoError([&] { bag->data(bag->messages("/json").at(0)); },
                            {dir.file("hand.mcap"), "Message record at offset", "/json", "'json'", "only cdr"}));
}

// A rosbag2 SQLite bag as rosbag2 (Iron and later) creates it.
void make_db3(const std::string& path,
              const std::vector<std::tuple<int, std::string, std::string, std::string>>& topics,
              const std::vector<std::tuple<int, int64_t, std::string>>& messages) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const char* schema =
      "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY,ros_distro TEXT NOT NULL);"
      "CREATE TABLE metadata(id INTEGER PRIMARY KEY,metadata_version INTEGER NOT NULL,metadata TEXT NOT NULL);"
      "CREATE TABLE topics(id INTEGER PRIMARY KEY,name TEXT NOT NULL,type TEXT NOT NULL,"
      "serialization_format TEXT NOT NULL,offered_qos_profiles TEXT NOT NULL,type_description_hash TEXT NOT NULL);"
      "CREATE TABLE messages(id INTEGER PRIMARY KEY,topic_id INTEGER NOT NULL,timestamp INTEGER NOT NULL,"
      "data BLOB NOT NULL);"
      "CREATE INDEX timestamp_idx ON messages (timestamp ASC);"
      "INSERT INTO schema VALUES (4, 'jazzy');";
  ASSERT_EQ(sqlite3_exec(db, schema, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_stmt* st = nullptr;
  sqlite3_prepare_v2(db, "INSERT INTO topics VALUES (?, ?, ?, ?, '', '')", -1, &st, nullptr);
  for (const auto& [id, name, type, format] : topics) {
    sqlite3_bind_int(st, 1, id);
    sqlite3_bind_text(st, 2, name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 3, type.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(st, 4, format.c_str(), -1, SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  sqlite3_prepare_v2(db, "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)", -1, &st, nullptr);
  for (const auto& [topic, time, data] : messages) {
    sqlite3_bind_int(st, 1, topic);
    sqlite3_bind_int64(st, 2, time);
    sqlite3_bind_blob(st, 3, data.data(), static_cast<int>(data.size()), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_reset(st);
  }
  sqlite3_finalize(st);
  sqlite3_close(db);
}

std::string odometry_at(int stamp) {
  StampedPose pose;
  pose.header.stamp_sec = stamp;
  pose.T_parent_child.translation().x() = stamp;
  return encode_odometry(pose);
}

const std::vector<std::tuple<int, std::string, std::string, std::string>> kDb3Topics = {
    {1, "/points", "sensor_msgs/msg/PointCloud2", "cdr"},
    {2, "/odom", "nav_msgs/msg/Odometry", "cdr"},
    {3, "/diagnostics_json", "std_msgs/msg/String", "json"}};

TEST(BagDb3, TopicsAndMessagesInTimeOrder) {
  test::TempDir dir;
  RosHeader header;
  header.frame_id = "velodyne";
  const PointCloud cloud = test::random_cloud(50, 3);
  // Inserted out of time order; stamps 1 and 2 share a log time (row order decides).
  make_db3(dir.file("bag_0.db3"), kDb3Topics,
           {{2, 300, odometry_at(3)},
            {2, 100, odometry_at(0)},
            {2, 200, odometry_at(1)},
            {2, 200, odometry_at(2)},
            {1, 150, encode_point_cloud2(header, cloud)},
            {3, 160, "{\"level\": 0}"}});
  const std::unique_ptr<BagReader> bag = BagReader::open(dir.file("bag_0.db3"));
  ASSERT_EQ(bag->topics().size(), 3u);
  EXPECT_EQ(bag->topics()[1].name, "/odom");
  EXPECT_EQ(bag->topics()[1].type, "nav_msgs/msg/Odometry");
  EXPECT_EQ(bag->topics()[1].messages, 4u);
  const std::vector<BagMessageRef> odom = bag->messages("/odom");
  ASSERT_EQ(odom.size(), 4u);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(decode_odometry(bag->data(odom[k])).header.stamp_sec, k);
  EXPECT_EQ(odom[0].log_time_ns, 100u);
  const PointCloud2Message m = decode_point_cloud2(bag->data(bag->messages("/points").at(0)));
  EXPECT_TRUE(test::same_points(m.cloud.points, cloud));
  EXPECT_TRUE(ThrowsIoError([&] { bag->data(bag->messages("/diagnostics_json").at(0)); },
                            {"bag_0.db3", "table messages row 6", "/diagnostics_json", "'json'"}));
}

TEST(BagDb3, NotARosbag2Database) {
  test::TempDir dir;
  test::write_bytes(dir.file("junk.db3"), std::string(4096, 'x'));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("junk.db3")); }, {dir.file("junk.db3"), "table topics"}));
  sqlite3* db = nullptr;
  sqlite3_open(dir.file("other.db3").c_str(), &db);
  sqlite3_exec(db, "CREATE TABLE t(x);", nullptr, nullptr, nullptr);
  sqlite3_close(db);
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("other.db3")); }, {"table topics", "no such table"}));
}

std::string metadata_yaml(const std::string& storage, const std::vector<std::string>& files,
                          const std::string& compression = "") {
  std::string yaml = "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: " + storage +
                     "\n  duration:\n    nanoseconds: 900\n  message_count: 10\n  topics_with_message_count:\n"
                     "    - topic_metadata:\n        name: /odom\n        type: nav_msgs/msg/Odometry\n"
                     "        serialization_format: cdr\n      message_count: 10\n"
                     "  compression_format: \"" +
                     compression + "\"\n  compression_mode: \"\"\n  relative_file_paths:\n";
  for (const std::string& f : files) yaml += "    - " + f + "\n";
  yaml += "  files:\n";
  for (const std::string& f : files) yaml += "    - path: " + f + "\n      message_count: 5\n";
  return yaml;
}

TEST(BagFolder, MetadataYamlListsTwoDb3Files) {
  test::TempDir dir;
  const std::string folder = dir.file("rosbag2_drive");
  std::filesystem::create_directories(folder);
  // The split files overlap in time (a message received late lands in the second file).
  make_db3(folder + "/rosbag2_drive_0.db3", kDb3Topics,
           {{2, 0, odometry_at(0)}, {2, 10, odometry_at(1)}, {2, 30, odometry_at(3)}});
  make_db3(folder + "/rosbag2_drive_1.db3", {kDb3Topics[1]}, {{2, 20, odometry_at(2)}, {2, 40, odometry_at(4)}});
  test::write_bytes(folder + "/metadata.yaml",
                    metadata_yaml("sqlite3", {"rosbag2_drive_0.db3", "rosbag2_drive_1.db3"}));
  EXPECT_TRUE(BagReader::is_bag(folder));
  const std::unique_ptr<BagReader> bag = BagReader::open(folder);
  ASSERT_EQ(bag->topics().size(), 3u);
  EXPECT_EQ(bag->topics()[1].messages, 5u);
  const std::vector<BagMessageRef> odom = bag->messages("/odom");
  ASSERT_EQ(odom.size(), 5u);
  for (int k = 0; k < 5; ++k) EXPECT_EQ(decode_odometry(bag->data(odom[k])).header.stamp_sec, k);
  EXPECT_EQ(odom[2].c, 1u);
  EXPECT_EQ(BagReader::open(folder + "/metadata.yaml")->messages("/odom").size(), 5u);
}

TEST(BagFolder, McapFilesAndRefusals) {
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("b"));
  write_recording(dir.file("b/b_0.mcap"), {true, McapCompression::kLz4, 8000});
  test::write_bytes(dir.file("b/metadata.yaml"), metadata_yaml("mcap", {"b_0.mcap"}));
  check_recording(*BagReader::open(dir.file("b")));

  test::write_bytes(dir.file("z/metadata.yaml"), metadata_yaml("sqlite3", {"z_0.db3.zstd"}, "zstd"));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("z")); }, {"metadata.yaml", "compression_format 'zstd'"}));
  test::write_bytes(dir.file("m/metadata.yaml"), metadata_yaml("sqlite3", {"m_0.db3"}));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("m")); }, {"m_0.db3", "missing"}));
  std::filesystem::create_directories(dir.file("empty"));
  EXPECT_FALSE(BagReader::is_bag(dir.file("empty")));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("empty")); }, {"without metadata.yaml"}));
  EXPECT_TRUE(ThrowsIoError([&] { BagReader::open(dir.file("none.mcap")); }, {"missing file", "none.mcap"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
