// LOCALIZE_SEGMENTS payload (docs/protocol.md 5.5) and the parameters digest.
//
// Quantisation, and why it is safe:
//   * points: i16 offsets from the segment's centroid in steps of 2^e m, e the smallest in
//     [-16, 10] whose range holds the segment's farthest point: a point moves by at most
//     1/32767 of that reach (0.07 mm for a car, 1 mm for a facade 32 m long). Refinement is
//     an ICP that stops at 0.1 mm steps and may end in a flat direction, so a coarser step
//     (1 mm everywhere was tried) moved a few demo poses by up to 2 cm; at this one the two
//     paths agree as docs/protocol.md says.
//   * ESF: u16 mantissas of a power-of-two scale per segment (core/esf_quantization.h): rounding
//     moves a bin by at most 2^-16 of the largest one.
// Powers of two make re-encoding a decoded request give the same bytes (golden frames).
#include "segmatch/api/protocol.h"

#include "codec_util.h"

#include <segmatch/core/description/esf_quantization.h>
#include <segmatch/core/localization/localizer.h>

#include <algorithm>
#include <cmath>

namespace segmatch {
namespace api {
namespace {

using namespace detail;

constexpr size_t kSegmentsFixedBytes = 8 + 4 + 3 * 8 + 4 * 8 + 56 + 8 + 8 + 8 + 4 + 4;
static_assert(kSegmentsFixedBytes == 156, "docs/protocol.md documents 156 bytes");
constexpr size_t kSegmentBytes = 3 * 4 + kEigenFeatureCount * 4 + 4 + 1;  // centroid, eigen, n, step
static_assert(kSegmentBytes == 45, "docs/protocol.md documents 45 bytes");
constexpr size_t kEsfBytes = 1 + kEsfBins * 2;  // exponent, mantissas
constexpr int kI16Max = 32767;

// The smallest exponent e in [lo, hi] with max_abs / 2^e <= limit (hi if none is enough).
int exponent_for(double max_abs, double limit, int lo, int hi) {
  int e = lo;
  while (e < hi && max_abs > limit * std::ldexp(1.0, e)) ++e;
  return e;
}

// Step exponent of a segment's point offsets.
int point_exponent(const Segment& s) {
  double max_abs = 0.0;
  for (const Point& p : s.points)
    for (int k = 0; k < 3; ++k) max_abs = std::max(max_abs, std::abs(double(p.xyz()[k] - s.centroid[k])));
  return exponent_for(max_abs, kI16Max, kPointStepExponentMin, kPointStepExponentMax);
}

void put_points(wire::Writer& w, const Segment& s, int e) {
  const double inv = std::ldexp(1.0, -e);
  for (const Point& p : s.points)
    for (int k = 0; k < 3; ++k) {
      const double q = std::nearbyint(double(p.xyz()[k] - s.centroid[k]) * inv);
      w.u16(static_cast<uint16_t>(static_cast<int16_t>(std::clamp(q, -double(kI16Max), double(kI16Max)))));
    }
}

void put_esf(wire::Writer& w, const Segment& s) {
  const QuantizedEsf q = quantize_esf(s.esf, kEsfExponentMin, kEsfExponentMax);
  w.u8(static_cast<uint8_t>(static_cast<int8_t>(q.exponent)));
  for (uint16_t m : q.mantissas) w.u16(m);
}

bool all_finite(const float* v, size_t n) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(v[i])) return false;
  return true;
}

// One segment's fields; the points' count is checked against the total by the caller.
DecodeStatus get_segment(wire::Reader& r, bool esf, uint64_t index, Segment& s) {
  s.id = index;
  if (!r.f32s(s.centroid.data(), 3) || !r.f32s(s.eigen.data(), kEigenFeatureCount)) return DecodeStatus::kTruncated;
  if (!all_finite(s.centroid.data(), 3) || !all_finite(s.eigen.data(), kEigenFeatureCount))
    return DecodeStatus::kNonFinite;
  s.has_eigen = true;
  const uint32_t n = r.u32();
  const int step_e = static_cast<int8_t>(r.u8());
  if (r.failed()) return DecodeStatus::kTruncated;
  if (step_e < kPointStepExponentMin || step_e > kPointStepExponentMax) return DecodeStatus::kBadField;
  if (esf) {
    const int esf_e = static_cast<int8_t>(r.u8());
    if (esf_e < kEsfExponentMin || esf_e > kEsfExponentMax) return DecodeStatus::kBadField;
    const float scale = esf_scale(esf_e);
    for (float& v : s.esf) v = dequantize_esf_bin(r.u16(), scale);
    s.has_esf = true;
  }
  if (static_cast<uint64_t>(n) * kBytesPerSegmentPoint > r.remaining()) return DecodeStatus::kTruncated;
  const float step = static_cast<float>(std::ldexp(1.0, step_e));
  s.points.resize(n);
  for (Point& p : s.points) {
    for (int k = 0; k < 3; ++k) (&p.x)[k] = s.centroid[k] + static_cast<float>(static_cast<int16_t>(r.u16())) * step;
    p.intensity = 0.f;
  }
  return r.failed() ? DecodeStatus::kTruncated : DecodeStatus::kOk;
}

// Walks the segments' point counts before any value is read: they must add up to `points` and
// tile the payload up to `end` exactly (else a miscount would surface as whatever garbage it
// misaligns).
bool counts_add_up(const uint8_t* payload, size_t end, uint32_t count, uint32_t points, bool esf) {
  const uint64_t fixed = kSegmentBytes + (esf ? kEsfBytes : 0);
  uint64_t at = kSegmentsFixedBytes, seen = 0;
  for (uint32_t i = 0; i < count; ++i) {
    if (at + fixed > end) return false;
    wire::Reader n(payload + at + 40, 4);
    const uint32_t points_here = n.u32();
    seen += points_here;
    at += fixed + uint64_t{points_here} * kBytesPerSegmentPoint;
  }
  return at == end && seen == points;
}

}  // namespace

uint64_t segments_digest(const std::string& parameters_json) {
  uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a 64
  auto mix = [&h](uint8_t b) {
    h ^= b;
    h *= 0x100000001b3ull;
  };
  for (const char c : std::string("segmatch-segments/")) mix(static_cast<uint8_t>(c));
  for (int i = 0; i < 4; ++i) mix(static_cast<uint8_t>(kSegmentCodeVersion >> (8 * i)));
  for (const char c : parameters_json) mix(static_cast<uint8_t>(c));
  return h;
}

std::vector<uint8_t> encode(const LocalizeSegmentsRequest& m) {
  wire::Writer w;
  const bool esf = (m.flags & kSegmentsFlagEsf) != 0;
  size_t points = 0;
  for (const Segment& s : m.segments) points += s.points.size();
  w.reserve(kSegmentsFixedBytes + m.segments.size() * (kSegmentBytes + (esf ? kEsfBytes : 0)) +
            points * kBytesPerSegmentPoint);
  put_request_head(w, m);
  w.f64(m.prior_heading_tolerance_deg);
  w.u64(m.parameters_digest);
  w.u32(static_cast<uint32_t>(m.segments.size()));
  w.u32(static_cast<uint32_t>(points));
  for (const Segment& s : m.segments) {
    w.f32s(s.centroid.data(), 3);
    w.f32s(s.eigen.data(), kEigenFeatureCount);
    w.u32(static_cast<uint32_t>(s.points.size()));
    const int e = point_exponent(s);
    w.u8(static_cast<uint8_t>(static_cast<int8_t>(e)));
    if (esf) put_esf(w, s);
    put_points(w, s, e);
  }
  if (m.flags & kSegmentsFlagNewestScans) detail::put_newest_points(w, m.newest_points);  // revision 10
  return detail::frame(type_of(m), w);
}

DecodeStatus decode(const uint8_t* payload, size_t size, const Limits&, LocalizeSegmentsRequest& out) {
  if (size < kSegmentsFixedBytes) return DecodeStatus::kTruncated;
  wire::Reader r(payload, size);
  LocalizeSegmentsRequest m;
  const DecodeStatus s_head = get_request_head(r, m);
  m.prior_heading_tolerance_deg = r.f64();
  m.parameters_digest = r.u64();
  const uint32_t count = r.u32();
  const uint32_t points = r.u32();
  if (m.flags & ~kKnownSegmentsFlags) return DecodeStatus::kBadField;
  // Tracking (revision 11) registers the newest scans around the prior: both must be there.
  const uint32_t track_needs = kSegmentsFlagHasPrior | kSegmentsFlagNewestScans;
  if ((m.flags & kSegmentsFlagTrack) && (m.flags & track_needs) != track_needs) return DecodeStatus::kBadField;
  const bool esf = (m.flags & kSegmentsFlagEsf) != 0;
  // 64-bit arithmetic: no overflow for any u32 counts.
  const uint64_t segments_end = kSegmentsFixedBytes + uint64_t{count} * (kSegmentBytes + (esf ? kEsfBytes : 0)) +
                                uint64_t{points} * kBytesPerSegmentPoint;
  // With the newest scans (revision 10) their count and points follow the segments.
  const bool newest = (m.flags & kSegmentsFlagNewestScans) != 0;
  uint64_t newest_count = 0;
  if (newest) {
    if (segments_end + 4 > size) return DecodeStatus::kBadPointCount;
    wire::Reader n(payload + segments_end, 4);
    newest_count = n.u32();
    if (segments_end + 4 + newest_count * 12 != size) return DecodeStatus::kBadPointCount;
  } else if (segments_end != size) {
    return DecodeStatus::kBadPointCount;
  }
  if (!counts_add_up(payload, segments_end, count, points, esf)) return DecodeStatus::kBadPointCount;
  DecodeStatus s = s_head;
  if (s != DecodeStatus::kOk) return s;
  if (!std::isfinite(m.prior_radius_m) || !std::isfinite(m.prior_heading_tolerance_deg))
    return DecodeStatus::kNonFinite;
  if (m.prior_radius_m < 0.0 || m.prior_heading_tolerance_deg < 0.0) return DecodeStatus::kBadField;
  m.segments.resize(count);
  for (uint32_t i = 0; i < count; ++i) {
    s = get_segment(r, esf, i, m.segments[i]);
    if (s != DecodeStatus::kOk) return s;
  }
  if (newest) {
    r.u32();  // the count, read above
    s = detail::get_points(r, static_cast<uint32_t>(newest_count), 3, m.newest_points);
    if (s != DecodeStatus::kOk) return s;
  }
  s = detail::finish(r);
  if (s == DecodeStatus::kOk) out = std::move(m);
  return s;
}

}  // namespace api
}  // namespace segmatch
