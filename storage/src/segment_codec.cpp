#include "segment_codec.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>

namespace segmatch {
namespace storage {
namespace detail {

// ---------------------------------------------------------------------------------- XXH64
namespace {

constexpr uint64_t kP1 = 0x9E3779B185EBCA87ull;
constexpr uint64_t kP2 = 0xC2B2AE3D27D4EB4Full;
constexpr uint64_t kP3 = 0x165667B19E3779F9ull;
constexpr uint64_t kP4 = 0x85EBCA77C2B2AE63ull;
constexpr uint64_t kP5 = 0x27D4EB2F165667C5ull;

uint64_t rotl(uint64_t x, int r) { return (x << r) | (x >> (64 - r)); }
uint64_t read64(const uint8_t* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;
}
uint32_t read32(const uint8_t* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;
}
uint64_t round64(uint64_t acc, uint64_t input) { return rotl(acc + input * kP2, 31) * kP1; }
uint64_t merge64(uint64_t acc, uint64_t v) { return (acc ^ round64(0, v)) * kP1 + kP4; }

// The 32-byte stripes of inputs longer than 31 bytes, folded into one value.
uint64_t stripes(const uint8_t*& p, const uint8_t* end, uint64_t seed) {
  uint64_t v1 = seed + kP1 + kP2, v2 = seed + kP2, v3 = seed, v4 = seed - kP1;
  for (; end - p >= 32; p += 32) {
    v1 = round64(v1, read64(p));
    v2 = round64(v2, read64(p + 8));
    v3 = round64(v3, read64(p + 16));
    v4 = round64(v4, read64(p + 24));
  }
  uint64_t h = rotl(v1, 1) + rotl(v2, 7) + rotl(v3, 12) + rotl(v4, 18);
  for (uint64_t v : {v1, v2, v3, v4}) h = merge64(h, v);
  return h;
}

}  // namespace

// Bounds are compared as distances (end - p), never as p + n: SQLite hands a zero-length BLOB
// over as a null pointer, and null + 8 is undefined behaviour (found by fuzz_map, UBSan).
uint64_t xxh64(const void* data, size_t size, uint64_t seed) {
  const auto* p = static_cast<const uint8_t*>(data);
  const uint8_t* end = p + size;
  uint64_t h = size >= 32 ? stripes(p, end, seed) : seed + kP5;
  h += size;
  for (; end - p >= 8; p += 8) h = rotl(h ^ round64(0, read64(p)), 27) * kP1 + kP4;
  if (end - p >= 4) {
    h = rotl(h ^ (read32(p) * kP1), 23) * kP2 + kP3;
    p += 4;
  }
  for (; p < end; ++p) h = rotl(h ^ (*p * kP5), 11) * kP1;
  h ^= h >> 33;
  h *= kP2;
  h ^= h >> 29;
  h *= kP3;
  return h ^ (h >> 32);
}

// ------------------------------------------------------------------------- point encoding
namespace {

enum Encoding : uint32_t { kInt16 = 1, kFloat32 = 2 };

// Each of x, y, z, intensity is stored as an int16 q and decodes to offset + q * scale.
struct Header {
  uint32_t encoding;
  float offset[4];
  float scale[4];
};
static_assert(sizeof(Header) == 36, "blob header layout");
static_assert(sizeof(Point) == 4 * sizeof(float), "Point is x y z intensity");

constexpr double kMaxQ = 32767.0;
constexpr double kSteps[] = {0.002, 0.01};  // the two resolutions tried, finest first

struct Bounds {
  Eigen::Vector3f min, max;
  float intensity_min = 0.f, intensity_max = 0.f;
  bool all_finite = true;
};

Bounds bounds_of(const PointCloud& points, const Eigen::Vector3f& centroid) {
  Bounds b;
  const float inf = std::numeric_limits<float>::infinity();
  b.min.setConstant(inf);
  b.max.setConstant(-inf);
  float imin = inf, imax = -inf;
  for (const Point& p : points) {
    const Eigen::Vector3f xyz = p.xyz();
    if (!xyz.allFinite() || !std::isfinite(p.intensity)) b.all_finite = false;
    if (xyz.allFinite()) {
      b.min = b.min.cwiseMin(xyz);
      b.max = b.max.cwiseMax(xyz);
    }
    if (std::isfinite(p.intensity)) {
      imin = std::min(imin, p.intensity);
      imax = std::max(imax, p.intensity);
    }
  }
  if (!(b.min.array() <= b.max.array()).all()) b.min = b.max = centroid;  // no finite point
  if (imin <= imax) {
    b.intensity_min = imin;
    b.intensity_max = imax;
  }
  return b;
}

// Offsets at the centre of each range so that q spans -32767..32767.
Header int16_header(const Bounds& b, double step) {
  Header h{kInt16, {}, {}};
  for (int a = 0; a < 3; ++a) {
    h.offset[a] = static_cast<float>((double(b.min[a]) + b.max[a]) / 2);
    h.scale[a] = static_cast<float>(step);
  }
  h.offset[3] = static_cast<float>((double(b.intensity_min) + b.intensity_max) / 2);
  h.scale[3] = static_cast<float>((double(b.intensity_max) - b.intensity_min) / (2 * kMaxQ));
  return h;
}

// Nearest integer (halves up) of |x| <= kMaxQ without a branch on the sign, which random
// point offsets mispredict half the time, nor a libm call (std::lround is not inlined).
int16_t round_q(double x) { return static_cast<int16_t>(static_cast<int32_t>(x + (kMaxQ + 1.5)) - int32_t(kMaxQ + 1)); }

// False when a value does not fit (the caller then tries a coarser step).
bool encode_int16(const PointCloud& points, const Header& h, std::vector<uint8_t>* blob) {
  if (!std::isfinite(h.scale[3])) return false;
  double inverse[4];
  for (int j = 0; j < 4; ++j) inverse[j] = h.scale[j] > 0.f ? 1.0 / h.scale[j] : 0.0;
  blob->resize(sizeof(Header) + points.size() * 4 * sizeof(int16_t));
  std::memcpy(blob->data(), &h, sizeof(Header));
  uint8_t* out = blob->data() + sizeof(Header);
  for (const Point& p : points) {
    const float value[4] = {p.x, p.y, p.z, p.intensity};
    int16_t q[4];
    for (int j = 0; j < 4; ++j) {
      const double steps = (double(value[j]) - h.offset[j]) * inverse[j];
      if (j < 3 && !(std::fabs(steps) <= kMaxQ)) return false;
      q[j] = round_q(std::clamp(steps, -kMaxQ, kMaxQ));
    }
    std::memcpy(out, q, sizeof(q));
    out += sizeof(q);
  }
  return true;
}

void encode_float32(const PointCloud& points, std::vector<uint8_t>* blob) {
  const Header h{kFloat32, {}, {}};
  blob->resize(sizeof(Header) + points.size() * sizeof(Point));
  std::memcpy(blob->data(), &h, sizeof(Header));
  if (!points.empty()) {
    std::memcpy(blob->data() + sizeof(Header), points.data(), points.size() * sizeof(Point));
  }
}

// Decodes while the vector constructs its elements (vector::assign from an iterator range):
// one pass over fresh memory instead of zero-filling it first.
class Int16Points {
 public:
  using iterator_category = std::forward_iterator_tag;
  using value_type = Point;
  using difference_type = std::ptrdiff_t;
  using pointer = const Point*;
  using reference = Point;

  Int16Points(const uint8_t* at, const Header* h) : at_(at), h_(h) {}
  Point operator*() const {
    int16_t q[4];
    std::memcpy(q, at_, sizeof(q));  // blobs carry no alignment promise
    return {h_->offset[0] + q[0] * h_->scale[0], h_->offset[1] + q[1] * h_->scale[1],
            h_->offset[2] + q[2] * h_->scale[2], h_->offset[3] + q[3] * h_->scale[3]};
  }
  Int16Points& operator++() {
    at_ += kSize;
    return *this;
  }
  Int16Points operator++(int) {
    Int16Points old = *this;
    at_ += kSize;
    return old;
  }
  bool operator==(const Int16Points& o) const { return at_ == o.at_; }
  bool operator!=(const Int16Points& o) const { return at_ != o.at_; }

 private:
  static constexpr difference_type kSize = 4 * sizeof(int16_t);
  const uint8_t* at_;
  const Header* h_;
};

}  // namespace

EncodedPoints encode_points(const PointCloud& points, const Eigen::Vector3f& centroid) {
  EncodedPoints out;
  const Bounds b = bounds_of(points, centroid);
  out.box_min = b.min;
  out.box_max = b.max;
  if (b.all_finite) {
    for (double step : kSteps) {
      if (encode_int16(points, int16_header(b, step), &out.blob)) return out;
    }
  }
  encode_float32(points, &out.blob);
  return out;
}

std::string decode_points(BlobView blob, uint64_t num_points, PointCloud* points) {
  if (blob.is_null || blob.size < sizeof(Header)) return "point blob missing or too short";
  Header h;
  std::memcpy(&h, blob.data, sizeof(h));
  const auto* body = static_cast<const uint8_t*>(blob.data) + sizeof(Header);
  const size_t body_size = blob.size - sizeof(Header);
  if (h.encoding != kInt16 && h.encoding != kFloat32) {
    return "unknown point encoding " + std::to_string(h.encoding);
  }
  const size_t point_size = h.encoding == kFloat32 ? sizeof(Point) : 4 * sizeof(int16_t);
  if (num_points > body_size / point_size || body_size != num_points * point_size) {
    return "point blob holds " + std::to_string(body_size) + " bytes, expected " + std::to_string(num_points) +
           " points";
  }
  if (h.encoding == kFloat32) {
    points->resize(num_points);
    if (num_points) std::memcpy(points->data(), body, body_size);
  } else {
    points->assign(Int16Points(body, &h), Int16Points(body + body_size, &h));
  }
  return {};
}

std::string decode_int16_planes(const uint8_t* header, const uint8_t* planes, uint64_t num_points, PointCloud* points) {
  Header h;
  std::memcpy(&h, header, sizeof(h));
  if (h.encoding != kInt16) return "unknown point encoding " + std::to_string(h.encoding);
  const size_t n = static_cast<size_t>(num_points);
  points->resize(n);
  // Running sums of the x y z deltas (mod 2^16), then the same expression as Int16Points with
  // the intensity's q = 0, so that the floats are those of the schema-1 decode bit for bit.
  uint16_t running[3] = {0, 0, 0};
  for (size_t i = 0; i < n; ++i) {
    float xyz[3];
    for (int a = 0; a < 3; ++a) {
      const uint16_t delta = static_cast<uint16_t>(planes[(2 * a) * n + i] | planes[(2 * a + 1) * n + i] << 8);
      running[a] = static_cast<uint16_t>(running[a] + delta);
      xyz[a] = h.offset[a] + static_cast<int16_t>(running[a]) * h.scale[a];
    }
    (*points)[i] = {xyz[0], xyz[1], xyz[2], h.offset[3] + 0 * h.scale[3]};
  }
  return {};
}

// ------------------------------------------------------------------------ rows, checksums
uint64_t row_checksum(const SegmentRow& row) {
  // The scalars in a fixed byte layout, then the blobs: a changed byte anywhere in the row
  // (or a blob turned NULL) changes the sum.
  uint8_t record[64];
  size_t n = 0;
  const auto put = [&](const void* p, size_t size) {
    std::memcpy(record + n, p, size);
    n += size;
  };
  put(&row.segment_id, 8);
  put(&row.keyframe, 4);
  put(&row.label, 4);
  put(row.centroid.data(), 12);
  put(row.box_min.data(), 12);
  put(row.box_max.data(), 12);
  put(&row.num_points, 8);
  const uint8_t flags =
      uint8_t(!row.eigen.is_null) | uint8_t(!row.esf.is_null) << 1 | uint8_t(!row.points.is_null) << 2;
  put(&flags, 1);
  uint64_t h = xxh64(record, n, 0);
  for (const BlobView& blob : {row.eigen, row.esf, row.points}) {
    if (!blob.is_null) h = xxh64(blob.data, blob.size, h);
  }
  return h;
}

uint64_t classifier_checksum(const ClassifierBlob& classifier) {
  const uint64_t h = xxh64(classifier.format.data(), classifier.format.size(), 0);
  return xxh64(classifier.bytes.data(), classifier.bytes.size(), h);
}

BlobView eigen_blob(const Segment& segment) {
  if (!segment.has_eigen) return {};
  return {segment.eigen.data(), sizeof(segment.eigen), false};
}

BlobView esf_blob(const Segment& segment) {
  if (!segment.has_esf) return {};
  return {segment.esf.data(), sizeof(segment.esf), false};
}

namespace {

template <typename Array>
std::string copy_floats(BlobView blob, const char* what, Array* out, bool* present) {
  *present = !blob.is_null;
  if (blob.is_null) return {};
  if (blob.size != sizeof(*out)) {
    return std::string(what) + " blob has " + std::to_string(blob.size) + " bytes, expected " +
           std::to_string(sizeof(*out));
  }
  std::memcpy(out->data(), blob.data, sizeof(*out));
  return {};
}

}  // namespace

std::string decode_descriptors(const SegmentRow& row, Segment* segment) {
  segment->id = row.segment_id;
  segment->centroid = row.centroid;
  segment->label = row.label;
  std::string problem = copy_floats(row.eigen, "eigen", &segment->eigen, &segment->has_eigen);
  if (problem.empty()) problem = copy_floats(row.esf, "ESF", &segment->esf, &segment->has_esf);
  return problem;
}

}  // namespace detail
}  // namespace storage
}  // namespace segmatch
