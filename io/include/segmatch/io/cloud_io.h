// Point-cloud files: KITTI velodyne .bin (+ SemanticKITTI .label), PCD and PLY.
//
// The readers never trust their input: malformed, truncated or hostile files raise IoError
// (see error.h) naming the file and the problem, and points with a NaN/Inf coordinate are
// dropped (with their labels) so that they never reach the pipeline.
#pragma once

#include <segmatch/core/common/types.h>
#include <segmatch/io/error.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace segmatch {
namespace io {

struct CloudData {
  PointCloud points;              // finite points only
  std::vector<uint32_t> labels;   // one per point when the source has labels, else empty
  bool has_intensity = false;     // false => intensity filled with 0
  std::vector<uint16_t> rings;    // one per point when the source has a ring field (a ROS 2 PointCloud2's), else empty
  size_t dropped_non_finite = 0;  // points dropped because x, y or z was NaN/Inf
};

// KITTI velodyne scan: packed float32 records x y z intensity. A file whose size is not a
// multiple of 16 bytes is rejected (it is truncated or not a scan). A non-finite intensity is
// replaced by 0.
CloudData read_kitti_bin(const std::string& path);
void write_kitti_bin(const std::string& path, const PointCloud& cloud);

// SemanticKITTI .label: one uint32 per point (see encode_label in core/types.h).
std::vector<uint32_t> read_kitti_labels(const std::string& path);
void write_kitti_labels(const std::string& path, const std::vector<uint32_t>& labels);

enum class PcdEncoding { kAscii, kBinary, kBinaryCompressed };

// PCD v0.5-0.7, DATA ascii / binary / binary_compressed (LZF). Fields may come in any order
// and have any TYPE/SIZE (F4 F8 U1 U2 U4 U8 I1 I2 I4 I8); fields with COUNT > 1 (normals
// histograms, fpfh...) and unknown fields (rgb, normal_x...) are skipped. Requires x y z;
// reads "intensity" (or "i") and "label" when present.
CloudData read_pcd(const std::string& path);
// Writes fields x y z intensity (F4) and, when labels is given, label (U4). labels must have
// one entry per point.
void write_pcd(const std::string& path, const PointCloud& cloud, PcdEncoding encoding = PcdEncoding::kBinary,
               const std::vector<uint32_t>* labels = nullptr);

enum class PlyEncoding { kAscii, kBinaryLittleEndian };

// PLY ascii / binary_little_endian / binary_big_endian. Reads the "vertex" element's x y z,
// "intensity" (or "scalar_intensity") and "label" (or "scalar_label"); every other property
// (including list properties) and every other element (faces...) is skipped.
CloudData read_ply(const std::string& path);
// Writes a vertex element with float x y z intensity.
void write_ply(const std::string& path, const PointCloud& cloud,
               PlyEncoding encoding = PlyEncoding::kBinaryLittleEndian);

// Dispatch on the extension (.bin, .pcd, .ply; case-insensitive). Unknown extension => IoError.
CloudData read_cloud(const std::string& path);
// .bin => KITTI, .pcd => binary PCD, .ply => binary little-endian PLY.
void write_cloud(const std::string& path, const PointCloud& cloud);

}  // namespace io
}  // namespace segmatch
