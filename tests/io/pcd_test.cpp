// PCD: round trips of the three encodings and hand-written files in the shapes other tools
// produce (extra fields, other field orders and types, organised clouds, CRLF, LZF).
#include <segmatch/io/cloud_io.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "io_test_util.h"

namespace segmatch {
namespace io {
namespace {

using test::ThrowsIoError;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

std::string pcd_header(const std::string& fields, const std::string& sizes, const std::string& types,
                       const std::string& counts, size_t points, const std::string& data) {
  return "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " + sizes + "\nTYPE " +
         types + "\nCOUNT " + counts + "\nWIDTH " + std::to_string(points) +
         "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + std::to_string(points) + "\nDATA " + data + "\n";
}

class PcdRoundTrip : public ::testing::TestWithParam<PcdEncoding> {};

TEST_P(PcdRoundTrip, PointsAndLabelsSurviveExactly) {
  test::TempDir dir;
  const PointCloud cloud = test::random_cloud(2000, 21);
  const std::vector<uint32_t> labels = test::random_labels(2000, 22);
  write_pcd(dir.file("plain.pcd"), cloud, GetParam());
  write_pcd(dir.file("labeled.pcd"), cloud, GetParam(), &labels);
  const CloudData plain = read_pcd(dir.file("plain.pcd"));
  EXPECT_TRUE(test::same_points(plain.points, cloud));
  EXPECT_TRUE(plain.has_intensity);
  EXPECT_TRUE(plain.labels.empty());
  const CloudData labeled = read_pcd(dir.file("labeled.pcd"));
  EXPECT_TRUE(test::same_points(labeled.points, cloud));
  EXPECT_EQ(labeled.labels, labels);
}

TEST_P(PcdRoundTrip, EmptyCloud) {
  test::TempDir dir;
  write_pcd(dir.file("empty.pcd"), {}, GetParam());
  const CloudData data = read_pcd(dir.file("empty.pcd"));
  EXPECT_TRUE(data.points.empty());
  EXPECT_EQ(data.dropped_non_finite, 0u);
}

TEST_P(PcdRoundTrip, NonFinitePointsDroppedWithTheirLabels) {
  test::TempDir dir;
  PointCloud cloud = test::random_cloud(6, 23);
  cloud[1].y = kNaN;
  cloud[4].x = -std::numeric_limits<float>::infinity();
  const std::vector<uint32_t> labels = {10, 11, 12, 13, 14, 15};
  write_pcd(dir.file("nan.pcd"), cloud, GetParam(), &labels);
  const CloudData data = read_pcd(dir.file("nan.pcd"));
  EXPECT_EQ(data.dropped_non_finite, 2u);
  EXPECT_EQ(data.labels, (std::vector<uint32_t>{10, 12, 13, 15}));
  ASSERT_EQ(data.points.size(), 4u);
  EXPECT_EQ(data.points[3].x, cloud[5].x);
}

std::string encoding_name(const ::testing::TestParamInfo<PcdEncoding>& info) {
  switch (info.param) {
    case PcdEncoding::kAscii: return "Ascii";
    case PcdEncoding::kBinary: return "Binary";
    case PcdEncoding::kBinaryCompressed: return "BinaryCompressed";
  }
  return "Unknown";
}

INSTANTIATE_TEST_SUITE_P(AllEncodings, PcdRoundTrip,
                         ::testing::Values(PcdEncoding::kAscii, PcdEncoding::kBinary, PcdEncoding::kBinaryCompressed),
                         encoding_name);

TEST(Pcd, LabelCountMustMatchPoints) {
  test::TempDir dir;
  const std::vector<uint32_t> labels(3, 1);
  EXPECT_TRUE(
      ThrowsIoError([&] { write_pcd(dir.file("l.pcd"), test::random_cloud(4, 1), PcdEncoding::kBinary, &labels); },
                    {"l.pcd", "3 labels for 4 points"}));
}

TEST(Pcd, CompressedIsSmallerOnRepetitiveData) {
  test::TempDir dir;
  PointCloud cloud(5000);
  for (size_t i = 0; i < cloud.size(); ++i) cloud[i] = {float(i % 50), 2.0f, -1.5f, 0.25f};
  write_pcd(dir.file("bin.pcd"), cloud, PcdEncoding::kBinary);
  write_pcd(dir.file("lzf.pcd"), cloud, PcdEncoding::kBinaryCompressed);
  EXPECT_LT(std::filesystem::file_size(dir.file("lzf.pcd")) * 5, std::filesystem::file_size(dir.file("bin.pcd")));
  EXPECT_TRUE(test::same_points(read_pcd(dir.file("lzf.pcd")).points, cloud));
}

// An LZF stream written by hand (not by our compressor): a 4-byte literal run then one long
// overlapping back reference, as liblzf/PCL emit for repeated values.
TEST(Pcd, HandWrittenBinaryCompressed) {
  test::TempDir dir;
  std::string file = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, "binary_compressed");
  test::append_raw<uint32_t>(&file, 8);            // compressed size
  test::append_raw<uint32_t>(&file, 24);           // 2 points x 3 floats
  file += std::string("\x03\x00\x00\x80\x3f", 5);  // literal: 1.0f
  file += std::string("\xe0\x0b\x03", 3);          // copy 7+11+2 = 20 bytes from 4 back
  test::write_bytes(dir.file("hand.pcd"), file);
  const CloudData data = read_pcd(dir.file("hand.pcd"));
  ASSERT_EQ(data.points.size(), 2u);
  for (const Point& p : data.points) {
    EXPECT_EQ(p.x, 1.0f);
    EXPECT_EQ(p.y, 1.0f);
    EXPECT_EQ(p.z, 1.0f);
  }
  EXPECT_FALSE(data.has_intensity);
}

// Per-field arrays: the x values come first, then all y, then all z.
TEST(Pcd, BinaryCompressedStoresOneArrayPerField) {
  test::TempDir dir;
  std::string raw;
  for (float v : {1.f, 2.f, 3.f, 10.f, 20.f, 30.f, 100.f, 200.f, 300.f}) test::append_raw(&raw, v);
  std::string file = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, "binary_compressed");
  test::append_raw<uint32_t>(&file, 38);  // two literal runs: 32 + 4 bytes, plus 2 control bytes
  test::append_raw<uint32_t>(&file, 36);
  file += char(31) + raw.substr(0, 32) + char(3) + raw.substr(32);
  test::write_bytes(dir.file("soa.pcd"), file);
  const CloudData data = read_pcd(dir.file("soa.pcd"));
  ASSERT_EQ(data.points.size(), 3u);
  EXPECT_EQ(data.points[1].x, 2.0f);
  EXPECT_EQ(data.points[1].y, 20.0f);
  EXPECT_EQ(data.points[2].z, 300.0f);
}

// The shape PCL writes for PointXYZRGBNormal + label + a 33-bin FPFH histogram.
TEST(Pcd, ExtraFieldsAreSkipped) {
  test::TempDir dir;
  std::string file =
      pcd_header("normal_x normal_y normal_z x rgb fpfh y label z curvature intensity", "4 4 4 4 4 4 4 4 4 4 4",
                 "F F F F F F F U F F F", "1 1 1 1 1 33 1 1 1 1 1", 2, "binary");
  for (int i = 0; i < 2; ++i) {
    for (float n : {0.0f, 0.6f, 0.8f}) test::append_raw(&file, n);
    test::append_raw(&file, 1.5f + i);               // x
    test::append_raw<uint32_t>(&file, 0x00FF8000u);  // rgb
    for (int k = 0; k < 33; ++k) test::append_raw(&file, float(k));
    test::append_raw(&file, -2.5f - i);          // y
    test::append_raw<uint32_t>(&file, 40u + i);  // label
    test::append_raw(&file, 0.25f);              // z
    test::append_raw(&file, 0.01f);              // curvature
    test::append_raw(&file, 7.0f * i);           // intensity
  }
  test::write_bytes(dir.file("extra.pcd"), file);
  const CloudData data = read_pcd(dir.file("extra.pcd"));
  ASSERT_EQ(data.points.size(), 2u);
  EXPECT_EQ(data.points[1].x, 2.5f);
  EXPECT_EQ(data.points[1].y, -3.5f);
  EXPECT_EQ(data.points[1].z, 0.25f);
  EXPECT_EQ(data.points[1].intensity, 7.0f);
  EXPECT_EQ(data.labels, (std::vector<uint32_t>{40, 41}));
}

TEST(Pcd, DoubleXyzAndU2IntensityInAnotherOrder) {
  test::TempDir dir;
  std::string file = pcd_header("intensity z y x", "2 8 8 8", "U F F F", "1 1 1 1", 2, "binary");
  test::append_raw<uint16_t>(&file, 4000);
  for (double v : {3.0, 2.0, 1.0}) test::append_raw(&file, v);
  test::append_raw<uint16_t>(&file, 65535);
  for (double v : {-0.5, 1e-3, 123456.75}) test::append_raw(&file, v);
  test::write_bytes(dir.file("f8.pcd"), file);
  const CloudData data = read_pcd(dir.file("f8.pcd"));
  ASSERT_EQ(data.points.size(), 2u);
  EXPECT_EQ(data.points[0].x, 1.0f);
  EXPECT_EQ(data.points[0].z, 3.0f);
  EXPECT_EQ(data.points[0].intensity, 4000.0f);
  EXPECT_EQ(data.points[1].x, 123456.75f);
  EXPECT_EQ(data.points[1].y, 1e-3f);
  EXPECT_EQ(data.points[1].intensity, 65535.0f);
}

TEST(Pcd, MissingIntensityAndShortIntensityName) {
  test::TempDir dir;
  test::write_bytes(dir.file("xyz.pcd"), pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1, "ascii") + "1 2 3\n");
  const CloudData xyz = read_pcd(dir.file("xyz.pcd"));
  EXPECT_FALSE(xyz.has_intensity);
  ASSERT_EQ(xyz.points.size(), 1u);
  EXPECT_EQ(xyz.points[0].intensity, 0.0f);
  EXPECT_EQ(xyz.points[0].z, 3.0f);
  test::write_bytes(dir.file("i.pcd"),
                    pcd_header("x y z i", "4 4 4 1", "F F F U", "1 1 1 1", 1, "ascii") + "1 2 3 200\n");
  const CloudData i = read_pcd(dir.file("i.pcd"));
  EXPECT_TRUE(i.has_intensity);
  EXPECT_EQ(i.points[0].intensity, 200.0f);
}

// Hand-written ascii: comments, CRLF line ends, fields reordered, extra fields, nan values,
// an organised 3x2 cloud and no COUNT line (PCD v0.6 style).
TEST(Pcd, HandWrittenAscii) {
  test::TempDir dir;
  const std::string file =
      "# .PCD v.6 - written by hand\r\nVERSION .6\r\nFIELDS label rgb z y x intensity\r\n"
      "SIZE 4 4 4 4 4 4\r\nTYPE U F F F F F\r\nWIDTH 3\r\nHEIGHT 2\r\nPOINTS 6\r\nDATA ascii\r\n"
      "1 4.2108e+06 0.5 -1 2 10\r\n"
      "2 4.2108e+06 nan nan nan 11\r\n"
      "3 4.2108e+06 +1.5e1 2.25 -3 12\r\n"
      "\r\n"
      "4 0 1 1 inf 13\r\n"
      "5 0 -.5 0 0 14\r\n"
      "6 0 7 8 9 15\r\n";
  test::write_bytes(dir.file("hand.pcd"), file);
  const CloudData data = read_pcd(dir.file("hand.pcd"));
  EXPECT_EQ(data.dropped_non_finite, 2u);
  ASSERT_EQ(data.points.size(), 4u);
  EXPECT_EQ(data.labels, (std::vector<uint32_t>{1, 3, 5, 6}));
  EXPECT_EQ(data.points[0].x, 2.0f);
  EXPECT_EQ(data.points[0].y, -1.0f);
  EXPECT_EQ(data.points[0].z, 0.5f);
  EXPECT_EQ(data.points[1].z, 15.0f);
  EXPECT_EQ(data.points[2].z, -0.5f);
  EXPECT_EQ(data.points[3].intensity, 15.0f);
}

// Found by fuzzing (scripts/fuzz.sh pcd): 9.2e18 in an ascii integer label field was cast to
// int64 (undefined behaviour); it is now refused like any other invalid label.
TEST(Pcd, AsciiIntegerLabelBeyondInt64IsRefused) {
  test::TempDir dir;
  test::write_bytes(dir.file("a.pcd"),
                    pcd_header("x y z label", "4 4 4 4", "F F F U", "1 1 1 1", 2, "ascii") + "1 2 3 7\n4 5 6 9.3e18\n");
  EXPECT_TRUE(
      ThrowsIoError([&] { read_pcd(dir.file("a.pcd")); }, {"a.pcd", "line 13", "9.3e+18 is not a valid uint32 label"}));
  test::write_bytes(dir.file("b.pcd"),
                    pcd_header("x y z label", "4 4 4 4", "F F F I", "1 1 1 1", 1, "ascii") + "1 2 3 -1\n");
  EXPECT_EQ(read_pcd(dir.file("b.pcd")).labels, std::vector<uint32_t>{0xFFFFFFFFu});  // low 32 bits, as PCL
}

TEST(Pcd, TruncatedBinaryNamesTheSizes) {
  test::TempDir dir;
  std::string file = pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 9000, "binary");
  file += std::string(100000, '\0');
  test::write_bytes(dir.file("000003.pcd"), file);
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("000003.pcd")); },
                            {"000003.pcd: truncated: header declares 9000 points (144000 bytes of "
                             "data) but only 100000 bytes follow"}));
}

TEST(Pcd, TruncatedAscii) {
  test::TempDir dir;
  test::write_bytes(dir.file("a.pcd"), pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 3, "ascii") + "1 2 3\n4 5 6\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("a.pcd")); }, {"a.pcd", "truncated", "3 points", "only 2"}));
}

TEST(Pcd, AsciiLineWithWrongValueCount) {
  test::TempDir dir;
  test::write_bytes(dir.file("a.pcd"), pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, "ascii") + "1 2 3\n4 5\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("a.pcd")); }, {"a.pcd line 13", "expected 3 values, got 2"}));
  test::write_bytes(dir.file("b.pcd"), pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1, "ascii") + "1 two 3\n");
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("b.pcd")); }, {"b.pcd line 12", "'two' is not a number"}));
}

TEST(Pcd, CorruptCompressedData) {
  test::TempDir dir;
  write_pcd(dir.file("c.pcd"), test::random_cloud(100, 24), PcdEncoding::kBinaryCompressed);
  std::string bytes = test::read_bytes(dir.file("c.pcd"));
  const size_t data = bytes.find("binary_compressed\n") + 18;
  std::string wrong_size = bytes;
  wrong_size[data + 4] ^= 0x10;  // uncompressed size no longer matches the header
  test::write_bytes(dir.file("size.pcd"), wrong_size);
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("size.pcd")); }, {"size.pcd", "corrupt", "uncompressed size"}));
  std::string bad_stream = bytes;
  bad_stream[data + 8] = static_cast<char>(0xE0);  // back reference before the start
  test::write_bytes(dir.file("stream.pcd"), bad_stream);
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("stream.pcd")); }, {"stream.pcd", "corrupt"}));
}

TEST(Pcd, BadHeaders) {
  test::TempDir dir;
  struct Case {
    std::string content, expected;
  };
  const std::vector<Case> cases = {
      {"hello world\nthis is not a pcd\n", "not a PCD header line"},
      {"ply\nformat ascii 1.0\n", "'ply' is not a PCD keyword"},
      {"# only a comment\nVERSION 0.7\n", "no DATA line"},
      {"", "no DATA line"},
      {pcd_header("x y intensity", "4 4 4", "F F F", "1 1 1", 1, "ascii"), "missing field z"},
      {pcd_header("x y z", "4 4", "F F F", "1 1 1", 1, "ascii"), "inconsistent"},
      {pcd_header("x y z", "4 4 3", "F F F", "1 1 1", 1, "ascii"), "unsupported TYPE/SIZE F3"},
      {pcd_header("x y z", "4 4 4", "F F Q", "1 1 1", 1, "ascii"), "unknown TYPE 'Q'"},
      {pcd_header("x y z", "4 4 4", "F F F", "1 2 1", 1, "ascii"), "field y has COUNT 2"},
      {pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1, "zip"), "unsupported DATA encoding 'zip'"},
      {"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n",
       "POINTS 3 but WIDTH x HEIGHT = 4"},
      {"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH -2\nDATA ascii\n", "WIDTH value '-2'"},
  };
  for (const Case& c : cases) {
    test::write_bytes(dir.file("bad.pcd"), c.content);
    EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("bad.pcd")); }, {"bad.pcd", c.expected})) << c.content;
  }
}

TEST(Pcd, HugeDeclaredSizesFailCleanly) {
  test::TempDir dir;
  std::string file = pcd_header("x y z", "8 8 8", "F F F", "1 1 1", 0, "binary");
  file.replace(file.find("WIDTH 0"), 7, "WIDTH 18446744073709551615");
  file.replace(file.find("POINTS 0"), 8, "POINTS 18446744073709551615");
  test::write_bytes(dir.file("huge.pcd"), file + "abc");
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("huge.pcd")); }, {"huge.pcd", "truncated"}));
  std::string lzf = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 100000000, "binary_compressed");
  test::append_raw<uint32_t>(&lzf, 3);
  test::append_raw<uint32_t>(&lzf, 1200000000u);
  test::write_bytes(dir.file("bomb.pcd"), lzf + "abc");
  EXPECT_TRUE(ThrowsIoError([&] { read_pcd(dir.file("bomb.pcd")); }, {"bomb.pcd", "corrupt"}));
}

}  // namespace
}  // namespace io
}  // namespace segmatch
