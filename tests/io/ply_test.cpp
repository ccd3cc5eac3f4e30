// PLY: round trips and hand-written files (big endian, faces before/after the vertices,
// list properties inside the vertex element, extra properties).
#include <segmatch/io/cloud_io.h>

#include <limits>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::ThrowsIoError;

TEST(Ply, RoundTripBothEncodings) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(1500, 31);
  for (PlyEncoding encoding : {PlyEncoding::kAscii, PlyEncoding::kBinaryLittleEndian}) {
    write_ply(dir.file("c.ply"), cloud, encoding);
    const CloudData data = read_ply(dir.file("c.ply"));
    EXPECT_TRUE(test::same_points(data.points, cloud));
    EXPECT_TRUE(data.has_intensity);
    EXPECT_TRUE(data.labels.empty());
  }
  const std::string header = test::read_bytes(dir.file("c.ply")).substr(0, 24);
  EXPECT_EQ(header, "ply\nformat binary_little");
}

TEST(Ply, HandWrittenBigEndian) {
  test::TempDir dir;
  std::string file =
      "ply\nformat binary_big_endian 1.0\ncomment from a big-endian tool\n"
      "element vertex 3\nproperty double x\nproperty float y\nproperty float z\n"
      "property ushort scalar_intensity\nproperty int label\nend_header\n";
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double xs[3] = {1.25, -7.5, 3.0};
  const float ys[3] = {2.0f, nan, -0.125f};
  for (int i = 0; i < 3; ++i) {
    test::append_raw_big_endian(&file, xs[i]);
    test::append_raw_big_endian(&file, ys[i]);
    test::append_raw_big_endian(&file, 100.0f * float(i));
    test::append_raw_big_endian<uint16_t>(&file, static_cast<uint16_t>(1000 + i));
    test::append_raw_big_endian<int32_t>(&file, 70000 + i);
  }
  test::write_bytes(dir.file("be.ply"), file);
  const CloudData data = read_ply(dir.file("be.ply"));
  ASSERT_EQ(data.points.size(), 2u);
  EXPECT_EQ(data.dropped_non_finite, 1u);
  EXPECT_EQ(data.points[0].x, 1.25f);
  EXPECT_EQ(data.points[0].y, 2.0f);
  EXPECT_EQ(data.points[0].intensity, 1000.0f);
  EXPECT_EQ(data.points[1].x, 3.0f);
  EXPECT_EQ(data.points[1].y, -0.125f);
  EXPECT_EQ(data.points[1].z, 200.0f);
  EXPECT_EQ(data.labels, (std::vector<uint32_t>{70000, 70002}));
}

// Faces before the vertices, and a list property in the middle of the vertex element.
TEST(Ply, BinaryWithListsAndElementsBeforeVertex) {
  test::TempDir dir;
  std::string file =
      "ply\r\nformat binary_little_endian 1.0\r\nelement face 2\r\nproperty list uchar int "
      "vertex_indices\r\n"
      "property uchar flags\r\nelement vertex 2\r\nproperty float x\r\nproperty list ushort float "
      "extra\r\n"
      "property float y\r\nproperty float z\r\nproperty uchar red\r\nend_header\r\n";
  test::append_raw<uint8_t>(&file, 3);
  for (int32_t v : {0, 1, 2}) test::append_raw(&file, v);
  test::append_raw<uint8_t>(&file, 9);
  test::append_raw<uint8_t>(&file, 4);
  for (int32_t v : {0, 1, 1, 0}) test::append_raw(&file, v);
  test::append_raw<uint8_t>(&file, 9);
  for (int i = 0; i < 2; ++i) {
    test::append_raw(&file, 10.0f + i);
    test::append_raw<uint16_t>(&file, static_cast<uint16_t>(i * 2));
    for (int k = 0; k < i * 2; ++k) test::append_raw(&file, 99.0f);
    test::append_raw(&file, 20.0f + i);
    test::append_raw(&file, 30.0f + i);
    test::append_raw<uint8_t>(&file, 255);
  }
  test::write_bytes(dir.file("lists.ply"), file);
  const CloudData data = read_ply(dir.file("lists.ply"));
  ASSERT_EQ(data.points.size(), 2u);
  EXPECT_FALSE(data.has_intensity);
  EXPECT_EQ(data.points[1].x, 11.0f);
  EXPECT_EQ(data.points[1].y, 21.0f);
  EXPECT_EQ(data.points[1].z, 31.0f);
  EXPECT_EQ(data.points[1].intensity, 0.0f);
}

TEST(Ply, HandWrittenAsciiWithFaces) {
  test::TempDir dir;
  const std::string file =
      "ply\nformat ascii 1.0\ncomment made by hand\nobj_info test\n"
      "element camera 1\nproperty float fov\n"
      "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty float "
      "intensity\nproperty uint label\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
      "60.0\n"
      "0 0 0 0 0 1 255 0.5 7\n"
      "1 0 nan 0 0 1 255 0.6 8\n"
      "1 1 0 0 0 1 255 0.7 9\n"
      "0 1 -2.5e-1 0 0 1 255 0.8 10\n"
      "3 0 1 2\n"
      "3 0 2 3\n";
  test::write_bytes(dir.file("faces.ply"), file);
  const CloudData data = read_ply(dir.file("faces.ply"));
  ASSERT_EQ(data.points.size(), 3u);
  EXPECT_EQ(data.dropped_non_finite, 1u);
  EXPECT_EQ(data.labels, (std::vector<uint32_t>{7, 9, 10}));
  EXPECT_EQ(data.points[2].z, -0.25f);
  EXPECT_EQ(data.points[2].intensity, 0.8f);
}

TEST(Ply, AsciiFacesBeforeVertices) {
  test::TempDir dir;
  const std::string file =
      "ply\nformat ascii 1.0\nelement face 2\nproperty list uchar int vertex_indices\n"
      "element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
      "3 0 1 1\n4 0 1 1 0\n"
      "1 2 3\n4 5 6\n";
  test::write_bytes(dir.file("f.ply"), file);
  const CloudData data = read_ply(dir.file("f.ply"));
  ASSERT_EQ(data.points.size(), 2u);
  EXPECT_EQ(data.points[0].x, 1.0f);
  EXPECT_EQ(data.points[1].z, 6.0f);
}

TEST(Ply, TruncatedBinaryNamesTheSizes) {
  test::TempDir dir;
  write_ply(dir.file("t.ply"), test::random_cloud(100, 32));
  const std::string bytes = test::read_bytes(dir.file("t.ply"));
  test::write_bytes(dir.file("t.ply"), bytes.substr(0, bytes.size() - 10));
  EXPECT_TRUE(ThrowsIoError([&] { read_ply(dir.file("t.ply")); },
                            {"t.ply: truncated: header declares 100 vertex items (1600 bytes of "
                             "data) but only 1590 bytes follow"}));
}

TEST(Ply, TruncatedAscii) {
  test::TempDir dir;
  test::write_bytes(dir.file("a.ply"),
                    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n1 2 3\n4 5 6\n7 8\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_ply(dir.file("a.ply")); }, {"a.ply", "truncated", "item 2 of 3"}));
}

// Found by fuzzing (scripts/fuzz.sh ply): an ascii element with no properties and a count of
// trillions made the reader loop over nothing for hours.
TEST(Ply, AsciiElementWithoutPropertiesTakesNoTokensWhateverItsCount) {
  test::TempDir dir;
  test::write_bytes(dir.file("a.ply"),
                    "ply\nformat ascii 1.0\nelement tex 4129138213020\nelement vertex 2\nproperty float x\n"
                    "property float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n");
  const CloudData cloud = read_ply(dir.file("a.ply"));
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.points[1].x, 4.f);
}

TEST(Ply, BadFiles) {
  test::TempDir dir;
  const std::string vertex = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  struct Case {
    std::string content, expected;
  };
  const std::vector<Case> cases = {
      {"plx\nformat ascii 1.0\nend_header\n", "missing 'ply' magic"},
      {"# .PCD v0.7\nVERSION 0.7\n", "missing 'ply' magic"},
      {"", "missing 'ply' magic"},
      {"ply\nformat ascii 1.0\n" + vertex, "no end_header"},
      {"ply\n" + vertex + "end_header\n1 2 3\n", "no format line"},
      {"ply\nformat binary_middle_endian 1.0\n" + vertex + "end_header\n", "unknown format"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n",
       "unknown property type 'float128'"},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n", "property declared before any element"},
      {"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int "
       "vertex_indices\nend_header\n3 0 1 2\n",
       "no vertex element"},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 "
       "2\n",
       "no scalar property z"},
      {"ply\nformat ascii 1.0\n" + vertex + "end_header\n1 two 3\n", "'two' is not a number"},
      {"ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "element count '-1'"},
      {"ply\nformat ascii 1.0\nwhat is this\n", "unknown keyword 'what'"},
  };
  for (const Case& c : cases) {
    test::write_bytes(dir.file("bad.ply"), c.content);
    EXPECT_TRUE(ThrowsIoError([&] { read_ply(dir.file("bad.ply")); }, {"bad.ply", c.expected})) << c.content;
  }
}

TEST(Ply, HugeListLengthIsTruncationNotAllocation) {
  test::TempDir dir;
  std::string file =
      "ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list uint int "
      "vertex_indices\n"
      "element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  test::append_raw<uint32_t>(&file, 0xFFFFFFF0u);
  test::write_bytes(dir.file("list.ply"), file + "abcd");
  EXPECT_TRUE(ThrowsIoError([&] { read_ply(dir.file("list.ply")); }, {"list.ply", "truncated", "'face' item 0"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
