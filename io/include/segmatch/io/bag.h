// ROS 2 recordings without ROS: rosbag2 bags in MCAP (the default storage since ROS 2 Iron) or
// SQLite (.db3 plus metadata.yaml, the default through Humble) storage, and the CDR-encoded
// messages a LiDAR drive records (sensor_msgs/msg/PointCloud2, nav_msgs/msg/Odometry,
// geometry_msgs/msg/PoseStamped, tf2_msgs/msg/TFMessage).
//
// Every malformed input throws IoError naming the file, the record (its opcode or table and
// row) and the byte offset: a truncated file, a wrong magic, an unknown compression, a CDR
// payload shorter than its header says, a PointCloud2 whose row_step / point_step disagree
// with its data. The decoders see bytes only, so their errors name the message type, the field
// and the offset in the payload ("PointCloud2.data: 120000 bytes announced at offset 96, 4000
// left"); the caller knows the topic and time to add.
//
// Only CDR-encoded topics are read (MCAP message_encoding / rosbag2 serialization_format
// "cdr"): other topics are listed, and data() refuses their messages by topic name.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace segmatch {
namespace io {

// ---------------------------------------------------------------------------------------
// Reading a bag

inline constexpr size_t kBagHeadBytes = 128;

struct BagTopic {
  std::string name;  // "/points"
  std::string type;  // "sensor_msgs/msg/PointCloud2"
  size_t messages = 0;
};

// Where one message lies in the bag; opaque to callers (the reader's own locator: for MCAP the
// record's file offset, or its chunk's offset and 1 + its offset in the decompressed chunk; for
// .db3 the messages row id; in a rosbag2 folder, c is the index of the file).
struct BagMessageRef {
  uint64_t log_time_ns = 0;  // the recorder's receive time
  uint64_t a = 0, b = 0, c = 0;
  // The payload's first kBagHeadBytes bytes (fewer when it is shorter), kept when indexing read
  // the message anyway (a .db3, or an MCAP scan; empty when an MCAP summary indexed it): a stamped
  // message's header (decode_header) without reading the message again.
  std::string head;
};

// Opening indexes every message: an MCAP file from its summary section when that accounts for
// every message (no chunk decompressed), else by one scan of its data section (each chunk
// decompressed once); a .db3 file by one query.
// Not thread-safe: data() keeps the last decompressed chunk (reading a topic in order then
// decompresses each chunk once) and reuses one SQLite statement. Use one reader per thread.
class BagReader {
 public:
  // path: an .mcap file, a .db3 file, or a rosbag2 folder (metadata.yaml plus its .mcap or
  // .db3 files, read in the order metadata.yaml lists them; a folder's metadata.yaml itself is
  // accepted too). Bags compressed by rosbag2 (compression_format) are refused. Throws IoError.
  static std::unique_ptr<BagReader> open(const std::string& path);
  // Whether path looks like a bag (an .mcap or .db3 file, or a folder with metadata.yaml).
  static bool is_bag(const std::string& path);
  virtual ~BagReader() = default;

  virtual const std::string& path() const = 0;
  virtual const std::vector<BagTopic>& topics() const = 0;
  // The messages of one topic in log-time order (ties: the order in the file). Empty for an
  // unknown topic.
  virtual std::vector<BagMessageRef> messages(const std::string& topic) const = 0;
  // The message's serialized bytes (CDR, with its 4-byte encapsulation header). IoError for a
  // topic whose encoding is not cdr, and for damage found only now (a chunk's CRC, a row).
  virtual std::string data(const BagMessageRef& ref) const = 0;
};

// ---------------------------------------------------------------------------------------
// Decoding messages (CDR: little- or big-endian per the encapsulation header; alignment counted
// from after that header)

struct RosHeader {
  int32_t stamp_sec = 0;
  uint32_t stamp_nanosec = 0;
  std::string frame_id;
  double stamp_s() const { return stamp_sec + 1e-9 * stamp_nanosec; }
};

struct PointCloud2Message {
  RosHeader header;
  uint32_t height = 0, width = 0;
  CloudData cloud;              // finite points; intensity when a field "intensity" exists
  std::vector<uint16_t> rings;  // one per kept point when a field "ring" exists, else empty
};
// Any field order, offsets and point_step; is_bigendian either way; x, y, z as float32 or
// float64; intensity as any numeric type; ring as any integer type (its low 16 bits);
// organised (height > 1) and unorganised clouds; non-finite points dropped (counted in
// cloud.dropped_non_finite). IoError when x, y or z is missing, a field reaches past
// point_step, row_step * height differs from the data's size, or row_step < width * point_step.
PointCloud2Message decode_point_cloud2(std::string_view cdr);
// The std_msgs/Header every stamped message starts with, alone (a cloud's stamp and frame without
// decoding its points); `message` names the type in errors.
RosHeader decode_header(std::string_view cdr, const char* message);

// A pose of child_frame_id in header.frame_id: T_parent_child. The quaternion is normalised; a
// zero or non-finite quaternion, or a non-finite position, is an IoError.
struct StampedPose {
  RosHeader header;
  std::string child_frame_id;
  Pose3d T_parent_child = Pose3d::Identity();
};
StampedPose decode_odometry(std::string_view cdr);                 // nav_msgs/msg/Odometry (pose.pose)
StampedPose decode_pose_stamped(std::string_view cdr);             // geometry_msgs/msg/PoseStamped (child "")
std::vector<StampedPose> decode_tf_message(std::string_view cdr);  // tf2_msgs/msg/TFMessage

// ---------------------------------------------------------------------------------------
// Writing (segmatch-sim --bag, tests): MCAP with ros2msg schemas and CDR little-endian messages

enum class McapCompression { kNone, kZstd, kLz4 };

struct McapWriterOptions {
  bool chunked = true;  // false: messages outside chunks
  McapCompression compression = McapCompression::kZstd;
  size_t chunk_size_bytes = 4 * 1024 * 1024;  // uncompressed bytes per chunk
};

// Chunks carry their CRC-32, each is followed by its MessageIndex records, and the summary holds
// schemas, channels, statistics and chunk indexes with SummaryOffset records, so indexed readers
// can seek. Not thread-safe.
class McapWriter {
 public:
  McapWriter(const std::string& path, const McapWriterOptions& options = {});  // IoError
  ~McapWriter();  // closes if close() was not called (errors then are swallowed)
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;
  // A channel for topic with message type "pkg/msg/Name" (one of the four above; another type
  // is an IoError, as its schema could not be written); returns its id.
  uint16_t add_channel(const std::string& topic, const std::string& type);
  // Messages may come in any log-time order (readers sort); publish_time is set to log_time.
  void write(uint16_t channel, uint64_t log_time_ns, std::string_view cdr);
  void close();  // summary (schemas, channels, chunk indexes, statistics), footer, magic

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

std::string encode_point_cloud2(const RosHeader& header, const PointCloud& cloud);  // x y z intensity float32
std::string encode_odometry(const StampedPose& pose);
std::string encode_tf_message(const std::vector<StampedPose>& transforms);

// ---------------------------------------------------------------------------------------
// A recorded sequence as a bag

class Sequence;

// How write_sequence_bag lays a drive out, as a ROS 2 LiDAR drive records it: per scan, at its
// time, a PointCloud2 on points_topic in sensor_frame, an Odometry on odom_topic (sensor_frame in
// map_frame, the sequence's pose) and the same transform on /tf.
struct SequenceBagOptions {
  std::string points_topic = "/points";
  std::string odom_topic = "/odom";
  std::string map_frame = "map";
  std::string sensor_frame = "lidar";
  McapWriterOptions mcap;
};
// progress(done, total) after each scan when given. IoError on a write failure.
void write_sequence_bag(const Sequence& sequence, const std::string& path, const SequenceBagOptions& options = {},
                        const std::function<void(size_t, size_t)>& progress = {});

}  // namespace io
}  // namespace segmatch
