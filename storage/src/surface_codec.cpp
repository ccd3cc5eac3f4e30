#include "surface_codec.h"

#include "packed_blobs.h"
#include "segment_codec.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

namespace segmatch {
namespace storage {
namespace detail {

namespace {

constexpr uint8_t kInt16 = 1, kFloat32 = 2;
constexpr double kStep = 0.01;  // 1 cm: <= 5 mm error, 4 % of the 0.25 m leaf the layer is meant for
constexpr double kMaxQ = 32767.0;
// The encoding, the offsets x y z (float64), the voxel size in steps (u16).
constexpr size_t kInt16Header = 1 + 3 * sizeof(double) + 2;

int64_t voxel_steps(double leaf_m) { return std::clamp<int64_t>(std::llround(leaf_m / kStep), 1, 32767); }

// Each axis as q with v = offset + q * kStep. False when a point is too far from the offsets (a
// tile wider than 655 m, or heights spread over more): the tile is then stored as float32.
bool quantise(const PointCloud& points, const double offset[3], std::vector<int16_t>* q) {
  q->resize(3 * points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const float v[3] = {points[i].x, points[i].y, points[i].z};
    for (int a = 0; a < 3; ++a) {
      const double steps = (double(v[a]) - offset[a]) / kStep;
      if (!(std::fabs(steps) <= kMaxQ)) return false;
      (*q)[3 * i + a] = static_cast<int16_t>(std::lround(steps));
    }
  }
  return true;
}

// A quantised point on the voxel grid of `voxel` steps: q = cell * voxel + rest, 0 <= rest <
// voxel, the three cells (+ 32768) in `cells` and the rests in `rests`, 16 bits each, y x z.
struct Voxelised {
  uint64_t cells, rests;
  bool operator<(const Voxelised& o) const { return cells != o.cells ? cells < o.cells : rests < o.rests; }
};

// In the order of the voxel grid (y, then x, then z cells): along a row of ground or up a wall
// the next point is in the next cell, so the cells' deltas are mostly 0 and 1, and the rests
// (where in its voxel a point lies) are small numbers of their own that zstd packs well.
std::vector<Voxelised> voxel_order(const std::vector<int16_t>& q, int64_t voxel) {
  std::vector<Voxelised> sorted(q.size() / 3);
  for (size_t i = 0; i < sorted.size(); ++i) {
    uint64_t cells = 0, rests = 0;
    for (int a : {1, 0, 2}) {
      const int64_t value = q[3 * i + a];
      const int64_t cell = value >= 0 ? value / voxel : -((-value + voxel - 1) / voxel);
      cells = cells << 16 | static_cast<uint64_t>(cell + 32768);
      rests = rests << 16 | static_cast<uint64_t>(value - cell * voxel);
    }
    sorted[i] = {cells, rests};
  }
  std::sort(sorted.begin(), sorted.end());
  return sorted;
}

// A delta d (mod 2^16) as 2|d| or 2|d| - 1 for negative d: small steps either way leave the high
// byte 0, where two's complement would set it on every step back.
uint16_t zigzag(uint16_t d) { return static_cast<uint16_t>(d << 1 ^ -(d >> 15)); }
uint16_t unzigzag(uint16_t z) { return static_cast<uint16_t>(z >> 1 ^ -(z & 1)); }

// 12 byte planes of n bytes: the cells' deltas along the sorted points (mod 2^16, zigzag), then
// the rests, each as x low, x high, y low, y high, z low, z high.
std::vector<uint8_t> int16_planes(const std::vector<Voxelised>& sorted) {
  const size_t n = sorted.size();
  std::vector<uint8_t> planes(12 * n);
  const auto put = [&](size_t first_plane, size_t i, uint16_t v) {
    planes[first_plane * n + i] = static_cast<uint8_t>(v);
    planes[(first_plane + 1) * n + i] = static_cast<uint8_t>(v >> 8);
  };
  uint16_t previous[3] = {0, 0, 0};
  for (size_t i = 0; i < n; ++i) {
    const int shift[3] = {16, 32, 0};  // x y z in the y x z keys
    for (int a = 0; a < 3; ++a) {
      const auto cell = static_cast<uint16_t>(sorted[i].cells >> shift[a]);
      put(2 * a, i, zigzag(static_cast<uint16_t>(cell - previous[a])));
      put(6 + 2 * a, i, static_cast<uint16_t>(sorted[i].rests >> shift[a]));
      previous[a] = cell;
    }
  }
  return planes;
}

// The rare tile that does not fit int16: x y z float32 in 12 byte planes, exact.
std::vector<uint8_t> float32_planes(const PointCloud& points) {
  const size_t n = points.size();
  std::vector<uint8_t> planes(12 * n);
  for (size_t i = 0; i < n; ++i) {
    uint8_t bytes[12];
    std::memcpy(bytes, &points[i].x, 12);  // x y z: the first 12 bytes of a Point
    for (size_t b = 0; b < 12; ++b) planes[b * n + i] = bytes[b];
  }
  return planes;
}

}  // namespace

int64_t surface_tile_index(double v, double tile_m) {
  constexpr double lo = std::numeric_limits<int32_t>::min(), hi = std::numeric_limits<int32_t>::max();
  return static_cast<int64_t>(std::clamp(std::floor(v / tile_m), lo, hi));
}

std::vector<uint8_t> encode_surface_tile(const PointCloud& points, int32_t tile_x, int32_t tile_y, double tile_m,
                                         double leaf_m) {
  float z_min = 0.f, z_max = 0.f;
  for (size_t i = 0; i < points.size(); ++i) {
    z_min = i ? std::min(z_min, points[i].z) : points[i].z;
    z_max = i ? std::max(z_max, points[i].z) : points[i].z;
  }
  // The tile's centre and the middle of its heights, moved onto the voxel grid (anchored at 0,
  // as a voxel filter's is) so that a voxel's points share a cell.
  const int64_t voxel = voxel_steps(leaf_m);
  const double cell_m = double(voxel) * kStep,
               middle[3] = {(tile_x + 0.5) * tile_m, (tile_y + 0.5) * tile_m, (double(z_min) + z_max) / 2};
  double offset[3];
  for (int a = 0; a < 3; ++a) offset[a] = std::round(middle[a] / cell_m) * cell_m;
  std::vector<int16_t> q;
  std::vector<uint8_t> out;
  if (quantise(points, offset, &q)) {
    out.resize(kInt16Header);
    out[0] = kInt16;
    std::memcpy(out.data() + 1, offset, 3 * sizeof(double));
    const auto steps = static_cast<uint16_t>(voxel);
    std::memcpy(out.data() + 1 + 3 * sizeof(double), &steps, 2);
    compress_into(int16_planes(voxel_order(q, voxel)), &out);
  } else {
    out.push_back(kFloat32);
    compress_into(float32_planes(points), &out);
  }
  return out;
}

std::string decode_surface_tile(BlobView blob, uint64_t num_points, PointCloud* points) {
  const auto* bytes = static_cast<const uint8_t*>(blob.data);
  if (blob.is_null || blob.size < 1) return "surface tile blob missing or empty";
  if (bytes[0] != kInt16 && bytes[0] != kFloat32) return "unknown surface point encoding " + std::to_string(bytes[0]);
  const bool int16 = bytes[0] == kInt16;
  const size_t header = int16 ? kInt16Header : 1, width = 12;
  if (blob.size < header) return "surface tile blob too short";
  if (num_points > (uint64_t{1} << 36)) return "implausible point count " + std::to_string(num_points);
  const size_t n = static_cast<size_t>(num_points);
  thread_local std::vector<uint8_t> planes;  // kept: a query reads several tiles
  const std::string problem = decompress(bytes + header, blob.size - header, n * width, &planes);
  if (!problem.empty()) return "surface points: " + problem;
  points->resize(n);
  if (!int16) {
    for (size_t i = 0; i < n; ++i) {
      uint8_t xyz[12];
      for (size_t b = 0; b < 12; ++b) xyz[b] = planes[b * n + i];
      Point& p = (*points)[i];
      std::memcpy(&p.x, xyz, 12);
      p.intensity = 0.f;
    }
    return {};
  }
  double offset[3];
  uint16_t voxel = 0;
  std::memcpy(offset, bytes + 1, sizeof(offset));
  std::memcpy(&voxel, bytes + 1 + sizeof(offset), 2);
  if (!std::isfinite(offset[0]) || !std::isfinite(offset[1]) || !std::isfinite(offset[2]) || voxel == 0)
    return "surface tile header is damaged";
  const auto plane = [&](size_t first_plane, size_t i) {
    return static_cast<uint16_t>(planes[first_plane * n + i] | planes[(first_plane + 1) * n + i] << 8);
  };
  uint16_t cell[3] = {0, 0, 0};
  for (size_t i = 0; i < n; ++i) {
    float xyz[3];
    for (int a = 0; a < 3; ++a) {
      cell[a] = static_cast<uint16_t>(cell[a] + unzigzag(plane(2 * a, i)));
      const int32_t q = (int32_t{cell[a]} - 32768) * voxel + plane(6 + 2 * a, i);
      // In double, rounded once: the error is the quantisation's plus one float rounding.
      xyz[a] = static_cast<float>(offset[a] + q * kStep);
    }
    (*points)[i] = {xyz[0], xyz[1], xyz[2], 0.f};
  }
  return {};
}

uint64_t surface_tile_checksum(int32_t tile_x, int32_t tile_y, uint64_t num_points, BlobView blob) {
  uint8_t record[16];
  std::memcpy(record, &tile_x, 4);
  std::memcpy(record + 4, &tile_y, 4);
  std::memcpy(record + 8, &num_points, 8);
  const uint64_t h = xxh64(record, sizeof(record), 0);
  return blob.is_null ? h : xxh64(blob.data, blob.size, h);
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
