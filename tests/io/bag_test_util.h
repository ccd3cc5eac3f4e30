// Hand-built ROS 2 bytes for the bag tests, written independently of the library's own writers:
// CDR payloads in either byte order, PointCloud2 point records, and raw MCAP records; and a
// small recording written with McapWriter.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <segmatch/io/bag.h>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace test {

// A CDR payload: encapsulation header, then fields aligned to their size from after it.
class Cdr {
 public:
  explicit Cdr(bool big_endian = false) : big_(big_endian) {
    out_ = std::string("\x00", 1) + (big_endian ? '\x00' : '\x01') + std::string(2, '\0');
  }
  template <typename T>
  Cdr& put(T value) {
    while ((out_.size() - 4) % sizeof(T) != 0) out_.push_back('\0');
    if (big_) {
      append_raw_big_endian(&out_, value);
    } else {
      append_raw(&out_, value);
    }
    return *this;
  }
  Cdr& str(const std::string& s) {
    put<uint32_t>(static_cast<uint32_t>(s.size() + 1));
    out_ += s;
    out_.push_back('\0');
    return *this;
  }
  Cdr& header(int32_t sec, uint32_t nanosec, const std::string& frame) { return put(sec).put(nanosec).str(frame); }
  Cdr& raw(const std::string& bytes) {
    out_ += bytes;
    return *this;
  }
  const std::string& bytes() const { return out_; }

 private:
  bool big_;
  std::string out_;
};

// One point record of point_step bytes, values stored in the given byte order.
struct PointRecord {
  explicit PointRecord(size_t step, bool big) : bytes(step, '\0'), big_endian(big) {}
  template <typename T>
  PointRecord& set(size_t offset, T value) {
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof(T));
    for (size_t i = 0; i < sizeof(T); ++i) bytes[offset + i] = big_endian ? b[sizeof(T) - 1 - i] : b[i];
    return *this;
  }
  std::string bytes;
  bool big_endian;
};

struct CloudField {
  std::string name;
  uint32_t offset;
  uint8_t datatype;  // 1 INT8 ... 7 FLOAT32, 8 FLOAT64
};

struct Cloud2 {
  bool cdr_big_endian = false;
  uint32_t height = 1, width = 0;
  std::vector<CloudField> fields;
  bool is_bigendian = false;
  uint32_t point_step = 0, row_step = 0;
  std::string data;
  int64_t announced_data_size = -1;  // >= 0: the length written instead of data.size()

  std::string cdr() const {
    Cdr c(cdr_big_endian);
    c.header(1700000000, 250000000, "lidar").put(height).put(width);
    c.put<uint32_t>(static_cast<uint32_t>(fields.size()));
    for (const CloudField& f : fields) c.str(f.name).put(f.offset).put(f.datatype).put<uint32_t>(1);
    c.put<uint8_t>(is_bigendian ? 1 : 0).put(point_step).put(row_step);
    c.put<uint32_t>(static_cast<uint32_t>(announced_data_size >= 0 ? announced_data_size : data.size()));
    c.raw(data).put<uint8_t>(0);
    return c.bytes();
  }
};

// Raw MCAP: little-endian records, for files the writer would never produce.
class McapBytes {
 public:
  McapBytes() : out_("\x89MCAP0\r\n", 8) {}
  static std::string str(const std::string& s) {
    std::string out;
    append_raw<uint32_t>(&out, static_cast<uint32_t>(s.size()));
    return out + s;
  }
  static std::string u16(uint16_t v) { return as_bytes(v); }
  static std::string u32(uint32_t v) { return as_bytes(v); }
  static std::string u64(uint64_t v) { return as_bytes(v); }
  static std::string record(uint8_t opcode, const std::string& body) {
    return std::string(1, static_cast<char>(opcode)) + u64(body.size()) + body;
  }
  static std::string channel(uint16_t id, uint16_t schema, const std::string& topic, const std::string& encoding) {
    return record(0x04, u16(id) + u16(schema) + str(topic) + str(encoding) + u32(0));
  }
  static std::string message(uint16_t channel, uint64_t time, const std::string& data) {
    return record(0x05, u16(channel) + u32(0) + u64(time) + u64(time) + data);
  }
  static std::string chunk(const std::string& compression, const std::string& records, uint64_t uncompressed,
                           uint32_t crc = 0) {
    return record(0x06,
                  u64(0) + u64(0) + u64(uncompressed) + u32(crc) + str(compression) + u64(records.size()) + records);
  }
  McapBytes& add(const std::string& bytes) {
    out_ += bytes;
    return *this;
  }
  // DataEnd, an empty summary, the footer and the closing magic.
  std::string finish() const {
    return out_ + record(0x0F, u32(0)) + record(0x02, u64(0) + u64(0) + u32(0)) + std::string("\x89MCAP0\r\n", 8);
  }

 private:
  template <typename T>
  static std::string as_bytes(T v) {
    std::string out;
    append_raw(&out, v);
    return out;
  }
  std::string out_;
};

constexpr uint64_t kT0 = 1700000000000000000ull;  // ns

// /points: 5 clouds; /odom: 10 poses at 20 Hz whose stamp_sec is their index, messages 3 and 4
// written in swapped order (the reader must sort by log time); /tf: 5 messages of 2 transforms.
inline void write_recording(const std::string& path, const McapWriterOptions& options) {
  McapWriter writer(path, options);
  const uint16_t points = writer.add_channel("/points", "sensor_msgs/msg/PointCloud2");
  const uint16_t odom = writer.add_channel("/odom", "nav_msgs/msg/Odometry");
  const uint16_t tf = writer.add_channel("/tf", "tf2_msgs/msg/TFMessage");
  for (int k = 0; k < 10; ++k) {
    const int o = k == 3 ? 4 : k == 4 ? 3 : k;
    StampedPose pose;
    pose.header.stamp_sec = o;
    pose.header.frame_id = "odom";
    pose.child_frame_id = "base_link";
    pose.T_parent_child = Eigen::Translation3d(o, 0.5 * o, 0) * Eigen::AngleAxisd(0.1 * o, Eigen::Vector3d::UnitZ());
    writer.write(odom, kT0 + uint64_t(o) * 50000000, encode_odometry(pose));
    if (k % 2 != 0) continue;
    RosHeader header;
    header.stamp_sec = k / 2;
    header.frame_id = "velodyne";
    writer.write(points, kT0 + uint64_t(k) * 50000000 + 1, encode_point_cloud2(header, random_cloud(200, k)));
    writer.write(tf, kT0 + uint64_t(k) * 50000000 + 2, encode_tf_message({pose, pose}));
  }
  writer.close();
}

}  // namespace test
}  // namespace io
}  // namespace segmatch
