// KITTI .bin/.label files, extension dispatch, write failures and robustness against garbage.
#include <segmatch/io/cloud_io.h>
#include <segmatch/io/pose_io.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::SucceedsOrThrowsIoError;
using test::ThrowsIoError;

TEST(KittiBin, RoundTripIsBitExact) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(1000, 1);
  write_kitti_bin(dir.file("000000.bin"), cloud);
  EXPECT_EQ(std::filesystem::file_size(dir.file("000000.bin")), 16000u);
  const CloudData data = read_kitti_bin(dir.file("000000.bin"));
  EXPECT_TRUE(test::same_points(data.points, cloud));
  EXPECT_TRUE(data.has_intensity);
  EXPECT_TRUE(data.labels.empty());
  EXPECT_EQ(data.dropped_non_finite, 0u);
}

TEST(KittiBin, EmptyFileIsAnEmptyScan) {
  test::TempDir dir;
  test::write_bytes(dir.file("empty.bin"), "");
  EXPECT_TRUE(read_kitti_bin(dir.file("empty.bin")).points.empty());
}

TEST(KittiBin, TruncatedFileIsRejected) {
  test::TempDir dir;
  write_kitti_bin(dir.file("000003.bin"), test::random_cloud(10, 2));
  std::filesystem::resize_file(dir.file("000003.bin"), 155);
  EXPECT_TRUE(
      ThrowsIoError([&] { read_kitti_bin(dir.file("000003.bin")); }, {"000003.bin", "155 bytes", "multiple of 16"}));
}

TEST(KittiBin, NonFinitePointsAreDroppedAndCounted) {
  test::TempDir dir;
  PointCloud cloud = test::random_cloud(10, 3);
  cloud[3].x = std::numeric_limits<float>::quiet_NaN();
  cloud[7].z = std::numeric_limits<float>::infinity();
  cloud[5].intensity = std::numeric_limits<float>::quiet_NaN();
  write_kitti_bin(dir.file("nan.bin"), cloud);
  const CloudData data = read_kitti_bin(dir.file("nan.bin"));
  ASSERT_EQ(data.points.size(), 8u);
  EXPECT_EQ(data.dropped_non_finite, 2u);
  EXPECT_EQ(data.points[3].x, cloud[4].x);    // point 3 was dropped
  EXPECT_EQ(data.points[4].intensity, 0.0f);  // original point 5: NaN intensity zeroed
  EXPECT_EQ(data.points[7].y, cloud[9].y);
}

TEST(KittiLabels, RoundTripAndTruncation) {
  test::TempDir dir;
  const std::vector<uint32_t> labels = test::random_labels(500, 4);
  write_kitti_labels(dir.file("000000.label"), labels);
  EXPECT_EQ(read_kitti_labels(dir.file("000000.label")), labels);
  std::filesystem::resize_file(dir.file("000000.label"), 1999);
  EXPECT_TRUE(ThrowsIoError([&] { read_kitti_labels(dir.file("000000.label")); }, {"000000.label", "multiple of 4"}));
}

TEST(CloudIo, MissingFileIsNamed) {
  test::TempDir dir;
  for (const std::string name : {"nope.bin", "nope.pcd", "nope.ply", "nope.label", "poses.txt"}) {
    const std::string path = dir.file(name);
    EXPECT_TRUE(ThrowsIoError(
        [&] {
          if (name == "nope.label")
            read_kitti_labels(path);
          else if (name == "poses.txt")
            read_kitti_poses(path);
          else
            read_cloud(path);
        },
        {"missing file: " + path}));
  }
}

TEST(CloudIo, DirectoryInsteadOfFile) {
  test::TempDir dir;
  std::filesystem::create_directories(dir.file("scan.pcd"));
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("scan.pcd")); }, {"scan.pcd", "directory"}));
}

TEST(CloudIo, DispatchByExtension) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(300, 5);
  for (const std::string name : {"a.bin", "a.pcd", "a.ply", "b.PCD"}) {
    write_cloud(dir.file(name), cloud);
    const CloudData data = read_cloud(dir.file(name));
    EXPECT_TRUE(test::same_points(data.points, cloud)) << name;
    EXPECT_TRUE(data.has_intensity) << name;
  }
  // Each extension really produced its own format.
  EXPECT_EQ(test::read_bytes(dir.file("a.pcd")).rfind("# .PCD v0.7", 0), 0u);
  EXPECT_EQ(test::read_bytes(dir.file("a.ply")).rfind("ply\n", 0), 0u);
  EXPECT_EQ(std::filesystem::file_size(dir.file("a.bin")), 300u * 16u);
}

TEST(CloudIo, UnknownExtensionIsNamed) {
  test::TempDir dir;
  test::write_bytes(dir.file("cloud.xyz"), "1 2 3\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_cloud(dir.file("cloud.xyz")); }, {"cloud.xyz", "'.xyz'", "extension"}));
  EXPECT_TRUE(ThrowsIoError([&] { write_cloud(dir.file("cloud.las"), {}); }, {"cloud.las", "extension"}));
  EXPECT_TRUE(ThrowsIoError([&] { read_cloud(dir.file("noext")); }, {"noext", "extension"}));
}

TEST(CloudIo, WriteIntoMissingFolderFails) {
  test::TempDir dir;
  const std::string path = dir.file("no/such/folder/scan.bin");
  EXPECT_TRUE(ThrowsIoError([&] { write_kitti_bin(path, test::random_cloud(3, 6)); }, {path, "cannot open"}));
}

TEST(CloudIo, DiskFullIsReported) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "/dev/full not available";
  const PointCloud cloud = test::random_cloud(20000, 7);  // larger than any stdio buffer
  EXPECT_TRUE(ThrowsIoError([&] { write_kitti_bin("/dev/full", cloud); }, {"/dev/full", "No space"}));
  EXPECT_TRUE(ThrowsIoError([&] { write_pcd("/dev/full", cloud, PcdEncoding::kAscii); }, {"/dev/full", "No space"}));
  EXPECT_TRUE(ThrowsIoError([&] { write_pcd("/dev/full", cloud, PcdEncoding::kBinaryCompressed); }, {"/dev/full"}));
  EXPECT_TRUE(ThrowsIoError([&] { write_ply("/dev/full", cloud); }, {"/dev/full", "No space"}));
  // Small outputs stay in the stdio buffer until close: the close must be checked too.
  EXPECT_TRUE(ThrowsIoError([&] { write_kitti_labels("/dev/full", {1, 2, 3}); }, {"/dev/full", "No space"}));
  EXPECT_TRUE(ThrowsIoError([&] { write_kitti_poses("/dev/full", Poses(2, Pose3d::Identity())); }, {"/dev/full"}));
}

// Garbage of every size must give IoError (or, rarely, a valid empty cloud), never a crash.
TEST(CloudIo, RandomGarbageNeverCrashes) {
  test::TempDir dir;
  std::mt19937 rng(8);
  for (int round = 0; round < 200; ++round) {
    std::string bytes(rng() % 600, '\0');
    for (char& c : bytes) c = static_cast<char>(rng());
    if (round % 3 == 0)
      bytes = "# .PCD v0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 9\nDATA binary_compressed\n" + bytes;
    if (round % 3 == 1) bytes = "ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty float x\n" + bytes;
    for (const std::string name : {"g.bin", "g.pcd", "g.ply", "g.label"}) {
      test::write_bytes(dir.file(name), bytes);
      EXPECT_TRUE(SucceedsOrThrowsIoError([&] {
        if (name == "g.label")
          read_kitti_labels(dir.file(name));
        else
          read_cloud(dir.file(name));
      })) << name
          << " round " << round;
    }
    test::write_bytes(dir.file("poses.txt"), bytes);
    EXPECT_TRUE(SucceedsOrThrowsIoError([&] { read_kitti_poses(dir.file("poses.txt")); }));
    EXPECT_TRUE(SucceedsOrThrowsIoError([&] { read_tum(dir.file("poses.txt")); }));
    EXPECT_TRUE(SucceedsOrThrowsIoError([&] { read_kitti_calib(dir.file("poses.txt")); }));
  }
}

// Every prefix of a valid binary file is either the whole file or an error.
TEST(CloudIo, EveryTruncationOfBinaryFilesIsAnError) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(6, 9);
  const std::vector<uint32_t> labels = test::random_labels(6, 9);
  write_pcd(dir.file("b.pcd"), cloud, PcdEncoding::kBinary, &labels);
  write_pcd(dir.file("c.pcd"), cloud, PcdEncoding::kBinaryCompressed, &labels);
  write_ply(dir.file("b.ply"), cloud, PlyEncoding::kBinaryLittleEndian);
  for (const std::string name : {"b.pcd", "c.pcd", "b.ply"}) {
    const std::string full = test::read_bytes(dir.file(name));
    for (size_t n = 0; n < full.size(); ++n) {
      test::write_bytes(dir.file("t_" + name), full.substr(0, n));
      EXPECT_TRUE(ThrowsIoError([&] { read_cloud(dir.file("t_" + name)); }, {"t_" + name}))
          << name << " cut at " << n << " of " << full.size();
    }
  }
}

// Flipped bytes in valid files (ascii and binary) must not crash the readers.
TEST(CloudIo, CorruptedBytesNeverCrash) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(40, 10);
  write_pcd(dir.file("a.pcd"), cloud, PcdEncoding::kAscii);
  write_pcd(dir.file("c.pcd"), cloud, PcdEncoding::kBinaryCompressed);
  write_ply(dir.file("a.ply"), cloud, PlyEncoding::kAscii);
  write_ply(dir.file("b.ply"), cloud, PlyEncoding::kBinaryLittleEndian);
  std::mt19937 rng(11);
  for (const std::string name : {"a.pcd", "c.pcd", "a.ply", "b.ply"}) {
    const std::string original = test::read_bytes(dir.file(name));
    for (int round = 0; round < 300; ++round) {
      std::string bytes = original;
      for (int k = 0; k < 1 + round % 4; ++k) bytes[rng() % bytes.size()] = static_cast<char>(rng());
      test::write_bytes(dir.file("x_" + name), bytes);
      EXPECT_TRUE(SucceedsOrThrowsIoError([&] { read_cloud(dir.file("x_" + name)); })) << name;
    }
  }
}

}  // namespace
}  // namespace io
}  // namespace segmatch
