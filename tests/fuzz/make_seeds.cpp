// Writes the seed corpora of the fuzz targets (tests/fuzz/corpus/<target>/) from the project's
// own writers: small valid inputs of every format and encoding, so that mutations start inside
// each format. Run by scripts/fuzz.sh --seeds; the outputs are committed.
#include <segmatch/api/protocol.h>
#include <segmatch/io/bag.h>
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/io/pose_io.h>
#include <segmatch/storage/map_writer.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace segmatch;

namespace {

std::string corpus;  // tests/fuzz/corpus

std::string seed(const std::string& target, const std::string& name) {
  fs::create_directories(corpus + "/" + target);
  return corpus + "/" + target + "/" + name;
}

// A prefix byte selects the reader in targets that read several formats.
void prefix_file(const std::string& path, uint8_t selector) {
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), {});
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.put(static_cast<char>(selector));
  out << bytes;
}

void write_bytes(const std::string& path, const std::vector<uint8_t>& bytes, int prefix = -1) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (prefix >= 0) out.put(static_cast<char>(prefix));
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

PointCloud small_cloud(size_t n) {
  PointCloud cloud;
  for (size_t i = 0; i < n; ++i) {
    const float a = 0.7f * float(i);
    cloud.push_back({10.f * std::cos(a), 10.f * std::sin(a), 0.1f * float(i), float(i % 7)});
  }
  return cloud;
}

Segment small_segment(uint64_t id) {
  Segment s;
  s.id = id;
  s.points = small_cloud(12);
  for (Point& p : s.points) p.x += 5.f * float(id);
  s.centroid = Eigen::Vector3f(5.f * float(id), 0.f, 0.5f);
  s.has_eigen = true;
  for (int i = 0; i < kEigenFeatureCount; ++i) s.eigen[i] = 0.1f * float(i + 1);
  s.has_esf = id % 2 == 0;
  for (int i = 0; i < kEsfBins; ++i) s.esf[i] = i % 3 == 0 ? 0.f : 1.f / 427.f;
  return s;
}

void cloud_seeds() {
  const std::vector<uint32_t> labels = {1, 2, 3, 40, 40, 44, 48, 50, 51, 70};
  const PointCloud cloud = small_cloud(10);
  io::write_pcd(seed("pcd", "ascii.pcd"), cloud, io::PcdEncoding::kAscii);
  io::write_pcd(seed("pcd", "binary.pcd"), cloud, io::PcdEncoding::kBinary);
  io::write_pcd(seed("pcd", "compressed.pcd"), cloud, io::PcdEncoding::kBinaryCompressed);
  io::write_pcd(seed("pcd", "labels.pcd"), cloud, io::PcdEncoding::kBinaryCompressed, &labels);
  io::write_pcd(seed("pcd", "empty.pcd"), PointCloud{}, io::PcdEncoding::kAscii);
  // Valid but extreme: one point, and coordinates 10,000 km from the origin.
  io::write_pcd(seed("pcd", "one_point.pcd"), small_cloud(1), io::PcdEncoding::kBinary);
  PointCloud far = cloud;
  for (Point& p : far) p.x += 1e7f, p.y -= 1e7f;
  io::write_pcd(seed("pcd", "far.pcd"), far, io::PcdEncoding::kBinaryCompressed);
  io::write_ply(seed("ply", "far.ply"), far, io::PlyEncoding::kAscii);
  io::write_ply(seed("ply", "ascii.ply"), cloud, io::PlyEncoding::kAscii);
  io::write_ply(seed("ply", "binary.ply"), cloud, io::PlyEncoding::kBinaryLittleEndian);
  io::write_kitti_bin(seed("kitti", "scan.bin"), cloud);
  prefix_file(seed("kitti", "scan.bin"), 0);
  io::write_kitti_labels(seed("kitti", "scan.label"), labels);
  prefix_file(seed("kitti", "scan.label"), 1);
}

void pose_seeds() {
  Poses poses;
  io::StampedPoses stamped;
  for (int k = 0; k < 3; ++k) {
    Pose3d T = Pose3d::Identity();
    T.rotate(Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ()));
    T.pretranslate(Eigen::Vector3d(2.0 * k, 0.5 * k, 0.0));
    poses.push_back(T);
    stamped.poses.push_back(T);
    stamped.times.push_back(0.1 * k);
  }
  io::write_kitti_poses(seed("poses", "poses.txt"), poses);
  prefix_file(seed("poses", "poses.txt"), 0);
  std::ofstream(seed("poses", "calib.txt")) << '\1' << "P0: 1 0 0 0 0 1 0 0 0 0 1 0\n"
                                            << "Tr: 0 -1 0 0 0 0 -1 0 1 0 0 -0.08\n";
  io::write_tum(seed("poses", "poses.tum"), stamped);
  prefix_file(seed("poses", "poses.tum"), 2);
  io::write_times(seed("poses", "times.txt"), stamped.times);
  prefix_file(seed("poses", "times.txt"), 3);
}

void config_seeds() {
  const std::string json = io::to_json(io::pipeline_preset("kitti-hdl64"));
  std::ofstream(seed("config", "pipeline.json"), std::ios::binary) << '\0' << json;
  std::ofstream(seed("config", "parameters.json"), std::ios::binary) << '\1' << json;
}

void frame_seeds() {
  api::LocalizeRequest localize;
  localize.request_id = 7;
  localize.points = small_cloud(5);
  write_bytes(seed("frame", "localize.bin"), api::encode(localize));
  localize.flags = api::kFlagHasPrior | api::kFlagPriorHeading;
  localize.prior_radius_m = 10.0;
  localize.prior_heading_tolerance_deg = 15.0;
  write_bytes(seed("frame", "localize_prior.bin"), api::encode(localize));
  api::LocalizeSegmentsRequest segments;
  segments.request_id = 8;
  segments.flags = api::kSegmentsFlagEsf;
  segments.segments = {small_segment(0), small_segment(2)};
  write_bytes(seed("frame", "localize_segments.bin"), api::encode(segments));
  api::LocalizeReply reply;
  reply.reason = "not localized: too few matches";
  reply.matched_segment_ids = {1, 2, 3};
  write_bytes(seed("frame", "localize_reply.bin"), api::encode(reply));
  api::InfoReply info;
  info.map_name = "seed";
  info.parameters_json = "{}";
  write_bytes(seed("frame", "info_reply.bin"), api::encode(info));
  write_bytes(seed("frame", "hello.bin"), api::encode(api::HelloRequest{"secret"}));
  write_bytes(seed("frame", "ping.bin"), api::encode(api::PingRequest{42}));
  write_bytes(seed("frame", "error.bin"), api::encode(api::ErrorReply{api::ErrorCode::kMalformed, "bad frame"}));
}

void map_seed() {
  storage::MapMetadata metadata;
  metadata.name = "seed";
  metadata.tool_version = "make_seeds";
  metadata.parameters_json = io::to_json(io::pipeline_preset("kitti-hdl64"));
  const std::string path = seed("map", "tiny.sqlite");
  storage::MapWriter writer = storage::MapWriter::create(path, metadata, true);
  writer.add_segments({small_segment(0), small_segment(1), small_segment(2)}, {0, 0, 1});
  std::vector<storage::Keyframe> trajectory(2);
  trajectory[1].index = 1;
  trajectory[1].time_s = 0.1;
  writer.set_trajectory(trajectory);
  writer.set_classifier({storage::kClassifierFormatRTreesYaml, "%YAML:1.0\n"});
  writer.commit();
}

// Small MCAP bags as segmatch-sim --bag writes them: a 3-point cloud, one odometry and one tf
// message, zstd-chunked (the rosbag2 default); lz4 and unchunked variants reach the other paths.
void bag_seeds() {
  struct Variant {
    const char* name;
    io::McapWriterOptions options;
  };
  const Variant variants[] = {{"zstd.mcap", {true, io::McapCompression::kZstd, 4096}},
                              {"lz4.mcap", {true, io::McapCompression::kLz4, 4096}},
                              {"unchunked.mcap", {false, io::McapCompression::kNone, 4096}}};
  for (const Variant& v : variants) {
    io::McapWriter writer(seed("bag", v.name), v.options);
    const uint16_t points = writer.add_channel("/points", "sensor_msgs/msg/PointCloud2");
    const uint16_t odom = writer.add_channel("/odom", "nav_msgs/msg/Odometry");
    const uint16_t tf = writer.add_channel("/tf", "tf2_msgs/msg/TFMessage");
    io::RosHeader header;
    header.stamp_sec = 1;
    header.frame_id = "velodyne";
    writer.write(points, 1000000000, io::encode_point_cloud2(header, small_cloud(3)));
    io::StampedPose pose;
    pose.header = header;
    pose.header.frame_id = "odom";
    pose.child_frame_id = "base_link";
    pose.T_parent_child.translation() = Eigen::Vector3d(1.0, 2.0, 0.5);
    writer.write(odom, 1000000001, io::encode_odometry(pose));
    writer.write(tf, 1000000002, io::encode_tf_message({pose}));
    writer.close();
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_FOLDER\n", argv[0]);
    return 2;
  }
  corpus = argv[1];
  cloud_seeds();
  pose_seeds();
  config_seeds();
  frame_seeds();
  map_seed();
  bag_seeds();
  return 0;
}
