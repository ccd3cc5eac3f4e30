// sensor_msgs/msg/PointCloud2 in CDR: the fields table says where x, y, z, intensity and ring
// sit in each point_step-byte record; the records are in the byte order is_bigendian says,
// which is independent of the CDR encapsulation's own byte order.
#include "cdr.h"
#include "scalar.h"

#include <cstring>

namespace segmatch {
namespace io {

namespace {

using detail::CdrReader;
using detail::ScalarKind;
using detail::ScalarType;

struct PointField {
  std::string name;
  uint32_t offset = 0;
  uint8_t datatype = 0;
  uint32_t count = 0;
};

// sensor_msgs/PointField datatypes INT8=1 ... FLOAT64=8; false for anything else.
bool scalar_of(uint8_t datatype, ScalarType* type) {
  static const ScalarType kTypes[8] = {
      {ScalarKind::kSigned, 1}, {ScalarKind::kUnsigned, 1}, {ScalarKind::kSigned, 2}, {ScalarKind::kUnsigned, 2},
      {ScalarKind::kSigned, 4}, {ScalarKind::kUnsigned, 4}, {ScalarKind::kFloat, 4},  {ScalarKind::kFloat, 8}};
  if (datatype < 1 || datatype > 8) return false;
  *type = kTypes[datatype - 1];
  return true;
}

std::string datatype_name(uint8_t datatype) {
  static const char* kNames[8] = {"INT8", "UINT8", "INT16", "UINT16", "INT32", "UINT32", "FLOAT32", "FLOAT64"};
  if (datatype < 1 || datatype > 8) return "unknown datatype " + std::to_string(datatype);
  return std::string(kNames[datatype - 1]) + " (" + std::to_string(datatype) + ")";
}

// Where one of the fields the decoder uses lies in a point record.
struct Slot {
  bool present = false;
  ScalarType type;
  size_t offset = 0;
};

struct Layout {
  Slot x, y, z, intensity, ring;
};

std::vector<PointField> read_fields(CdrReader& in) {
  // A PointField takes at least 4 (name length) + 4 + 1 + 4 bytes.
  std::vector<PointField> fields(in.sequence_count("fields", 13));
  for (PointField& f : fields) {
    f.name = in.string("fields.name");
    f.offset = in.u32("fields.offset");
    f.datatype = in.u8("fields.datatype");
    f.count = in.u32("fields.count");
  }
  return fields;
}

[[noreturn]] void fail(const std::string& problem) { throw IoError("PointCloud2" + problem); }

// Checks every field with a known datatype against point_step, and finds the ones we read.
Layout layout_of(const std::vector<PointField>& fields, uint32_t point_step) {
  Layout layout;
  std::string names;
  for (const PointField& f : fields) {
    names += (names.empty() ? "" : ", ") + f.name;
    ScalarType type;
    const bool known = scalar_of(f.datatype, &type);
    if (known) {
      const uint64_t end = uint64_t{f.offset} + uint64_t(type.size) * std::max<uint32_t>(f.count, 1);
      if (end > point_step) {
        fail(".fields[" + f.name + "]: offset " + std::to_string(f.offset) + " + " + std::to_string(end - f.offset) +
             " bytes = " + std::to_string(end) + " exceeds point_step " + std::to_string(point_step));
      }
    }
    Slot* slot = f.name == "x"           ? &layout.x
                 : f.name == "y"         ? &layout.y
                 : f.name == "z"         ? &layout.z
                 : f.name == "intensity" ? &layout.intensity
                 : f.name == "ring"      ? &layout.ring
                                         : nullptr;
    if (!slot || slot->present) continue;  // unused, or a duplicate name: the first one counts
    const bool is_xyz = slot != &layout.intensity && slot != &layout.ring;
    if (!known || (is_xyz && type.kind != ScalarKind::kFloat) ||
        (slot == &layout.ring && type.kind == ScalarKind::kFloat)) {
      fail(".fields[" + f.name + "]: datatype " + datatype_name(f.datatype) + " not supported (" +
           (is_xyz                 ? "x, y, z must be FLOAT32 or FLOAT64"
            : slot == &layout.ring ? "ring must be an integer type"
                                   : "intensity must be numeric") +
           ")");
    }
    *slot = Slot{true, type, f.offset};
  }
  for (const auto& [slot, name] : {std::pair{&layout.x, "x"}, {&layout.y, "y"}, {&layout.z, "z"}}) {
    if (!slot->present) fail(": no field '" + std::string(name) + "' (fields: " + names + ")");
  }
  return layout;
}

void check_sizes(uint32_t height, uint32_t width, uint32_t point_step, uint32_t row_step, size_t data_size) {
  const uint64_t rows_bytes = uint64_t{row_step} * height;
  if (rows_bytes != data_size) {
    fail(": data holds " + std::to_string(data_size) + " bytes but row_step " + std::to_string(row_step) +
         " * height " + std::to_string(height) + " = " + std::to_string(rows_bytes));
  }
  const uint64_t row_bytes = uint64_t{width} * point_step;
  if (row_bytes > row_step) {
    fail(": row_step " + std::to_string(row_step) + " is less than width " + std::to_string(width) + " * point_step " +
         std::to_string(point_step) + " = " + std::to_string(row_bytes));
  }
}

void decode_points(std::string_view data, uint32_t height, uint32_t width, uint32_t point_step, uint32_t row_step,
                   bool swap, const Layout& layout, PointCloud2Message* out) {
  const bool has_ring = layout.ring.present;
  detail::CloudBuilder builder(size_t{width} * height, layout.intensity.present, has_ring);
  const uint8_t* base = reinterpret_cast<const uint8_t*>(data.data());
  for (uint32_t r = 0; r < height; ++r) {
    for (uint32_t c = 0; c < width; ++c) {
      const uint8_t* p = base + size_t{r} * row_step + size_t{c} * point_step;
      const auto value = [&](const Slot& s) { return detail::load_double(p + s.offset, s.type, swap); };
      const float intensity = layout.intensity.present ? detail::to_float(value(layout.intensity)) : 0.f;
      // Ring numbers are small; wider integer fields keep their low 16 bits.
      const uint32_t ring =
          has_ring ? static_cast<uint16_t>(detail::load_integer(p + layout.ring.offset, layout.ring.type, swap)) : 0;
      builder.add(detail::to_float(value(layout.x)), detail::to_float(value(layout.y)),
                  detail::to_float(value(layout.z)), intensity, ring);
    }
  }
  out->cloud = builder.finish();
  // CloudBuilder keeps the rings as labels so that dropping a non-finite point drops its ring.
  out->rings.assign(out->cloud.labels.begin(), out->cloud.labels.end());
  out->cloud.labels.clear();
  out->cloud.labels.shrink_to_fit();
}

}  // namespace

RosHeader decode_header(std::string_view cdr, const char* message) {
  CdrReader in(cdr, message);
  return detail::read_ros_header(in);
}

PointCloud2Message decode_point_cloud2(std::string_view cdr) {
  CdrReader in(cdr, "PointCloud2");
  PointCloud2Message out;
  out.header = detail::read_ros_header(in);
  out.height = in.u32("height");
  out.width = in.u32("width");
  const std::vector<PointField> fields = read_fields(in);
  const bool is_bigendian = in.boolean("is_bigendian");
  const uint32_t point_step = in.u32("point_step");
  const uint32_t row_step = in.u32("row_step");
  const std::string_view data = in.bytes("data", in.u32("data"));
  in.boolean("is_dense");  // not trusted: non-finite points are dropped either way

  const Layout layout = layout_of(fields, point_step);
  check_sizes(out.height, out.width, point_step, row_step, data.size());
  decode_points(data, out.height, out.width, point_step, row_step, is_bigendian != detail::host_is_big_endian(), layout,
                &out);
  return out;
}

std::string encode_point_cloud2(const RosHeader& header, const PointCloud& cloud) {
  constexpr uint32_t kPointStep = sizeof(Point);  // x y z intensity, 4 x float32
  if (cloud.size() > UINT32_MAX / kPointStep) {
    throw IoError("PointCloud2: " + std::to_string(cloud.size()) + " points do not fit one message");
  }
  const uint32_t n = static_cast<uint32_t>(cloud.size());
  detail::CdrWriter out;
  detail::write_ros_header(out, header);
  out.u32(1);  // height: unorganised
  out.u32(n);  // width
  out.u32(4);
  const char* names[4] = {"x", "y", "z", "intensity"};
  for (uint32_t i = 0; i < 4; ++i) {
    out.string(names[i]);
    out.u32(4 * i);
    out.u8(7);  // FLOAT32
    out.u32(1);
  }
  out.boolean(detail::host_is_big_endian());  // the records are Point's bytes as they are in memory
  out.u32(kPointStep);
  out.u32(n * kPointStep);
  out.u32(n * kPointStep);
  if (n > 0) out.bytes(std::string_view(reinterpret_cast<const char*>(cloud.data()), n * kPointStep));
  out.boolean(true);  // is_dense: a PointCloud holds finite points only
  return out.take();
}

}  // namespace io
}  // namespace segmatch
