// Geometry of the objects of a generated world, built from boxes, vertical cylinders and
// ellipsoids. Shapes vary per instance (sizes, crowns, facade rhythm) while families stay
// recognisable (lamps of a street share a design), as in a real city.
#include "world_parts.h"

#include <algorithm>
#include <cmath>

namespace segmatch::sim::detail {
namespace {

using Eigen::Vector2f;
using Eigen::Vector3f;

Vector3f lift(const Vector2f& p, float z) { return {p.x(), p.y(), z}; }

WorldObject start_object(ObjectKind kind, uint16_t instance, const Vector2f& p, const Vector2f& half, float yaw,
                         float height) {
  WorldObject o;
  o.kind = kind;
  o.instance = instance;
  o.position = p;
  o.half_extents = half;
  o.yaw = yaw;
  o.height_m = height;
  return o;
}

// Box given in a side's local frame: s, o of its centre, half sizes along/inward, z range.
Primitive side_box(const SideFrame& side, float s, float o, float half_s, float half_o, float z0, float z1,
                   uint32_t label, float refl) {
  const Vector2f c = side.at(s, o);
  return Primitive::box(lift(c, 0.5f * (z0 + z1)), {half_s, half_o, 0.5f * (z1 - z0)}, side.yaw(), label, refl);
}

}  // namespace

float SideFrame::yaw() const { return std::atan2(along.y(), along.x()); }

float car_length(int model) {
  static const float kLength[kCarModels] = {3.7f, 4.3f, 4.7f, 4.9f, 5.4f};
  return kLength[model % kCarModels];
}

WorldObject make_building(PartBuilder& b, const SideFrame& side, float s0, float o0, float width, float depth,
                          float height) {
  Rng& rng = b.rng;
  const uint32_t label = encode_label(semantic::kBuilding, b.instance);
  const float refl = static_cast<float>(rng.uniform(0.25, 0.7));
  const Vector2f centre2 = side.at(s0 + 0.5f * width, o0 + 0.5f * depth);
  WorldObject obj =
      start_object(ObjectKind::kBuilding, b.instance, centre2, {0.5f * width, 0.5f * depth}, side.yaw(), height);
  // Seat the building on the lowest corner so no gap shows on a slope.
  float zmin = 1e9f;
  for (float fs : {0.0f, 1.0f})
    for (float fo : {0.0f, 1.0f}) zmin = std::min(zmin, b.ground(side.at(s0 + fs * width, o0 + fo * depth)));
  const float z0 = zmin - 0.3f;
  const float relief = 0.25f;  // window recess depth
  const bool arcade = rng.bernoulli(0.12) && height > 7.0f && depth > 10.0f;
  const float arcade_depth = 2.5f, arcade_height = 3.6f;
  const float sc = s0 + 0.5f * width;
  // Main mass, recessed by `relief` behind the facade plane at o0.
  if (arcade) {
    obj.parts.push_back(side_box(side, sc, o0 + 0.5f * depth, 0.5f * width, 0.5f * depth, z0 + arcade_height,
                                 z0 + height, label, refl));
    obj.parts.push_back(side_box(side, sc, o0 + arcade_depth + 0.5f * (depth - arcade_depth), 0.5f * width,
                                 0.5f * (depth - arcade_depth), z0, z0 + arcade_height, label, refl));
    for (float s = s0 + 0.6f; s < s0 + width - 0.3f; s += 4.0f) {
      obj.parts.push_back(Primitive::cylinder(lift(side.at(s, o0 + 0.4f), z0), 0.25f, arcade_height, label, refl));
    }
  } else {
    obj.parts.push_back(side_box(side, sc, o0 + relief + 0.5f * (depth - relief), 0.5f * width, 0.5f * (depth - relief),
                                 z0, z0 + height, label, refl));
  }
  // Facade relief: floor bands and pilasters at the facade plane leave recessed windows.
  const float floor_h = static_cast<float>(rng.uniform(2.9, 3.6));
  const float bay = static_cast<float>(rng.uniform(2.2, 3.6));
  const float pilaster = static_cast<float>(rng.uniform(0.4, 0.9));
  const float facade_z0 = arcade ? z0 + arcade_height : z0;
  const float o_band = o0 + 0.5f * relief;
  for (float z = facade_z0 + floor_h; z < z0 + height - 0.5f; z += floor_h) {
    obj.parts.push_back(side_box(side, sc, o_band, 0.5f * width, 0.5f * relief, z - 0.35f, z + 0.35f, label, refl));
  }
  const int bays = std::max(1, static_cast<int>(width / bay));
  const float bay_w = width / bays;
  const int door_bay = static_cast<int>(rng.index(static_cast<uint64_t>(bays)));
  for (int i = 0; i <= bays; ++i) {
    const float s = std::clamp(s0 + i * bay_w, s0 + 0.5f * pilaster, s0 + width - 0.5f * pilaster);
    const bool by_door = !arcade && (i == door_bay || i == door_bay + 1);
    obj.parts.push_back(side_box(side, s, o_band, 0.5f * pilaster, 0.5f * relief, by_door ? z0 : facade_z0 + 0.9f,
                                 z0 + height, label, refl));
  }
  // Ground-floor plinth under the windows (absent at the door).
  if (!arcade) {
    obj.parts.push_back(side_box(side, sc, o_band, 0.5f * width, 0.5f * relief, z0, zmin + 0.9f, label, refl));
  }
  // Balconies: slab and railing in front of every other bay of the upper floors.
  if (rng.bernoulli(0.4) && height > 7.0f) {
    const float depth_b = static_cast<float>(rng.uniform(0.9, 1.5));
    for (float z = facade_z0 + floor_h; z < z0 + height - floor_h; z += floor_h) {
      for (int i = (door_bay % 2); i < bays; i += 2) {
        const float s = s0 + (i + 0.5f) * bay_w;
        const float half = 0.5f * (bay_w - pilaster) + 0.3f;
        obj.parts.push_back(
            side_box(side, s, o0 - 0.5f * depth_b, half, 0.5f * depth_b, z - 0.1f, z + 0.08f, label, refl));
        obj.parts.push_back(side_box(side, s, o0 - depth_b + 0.03f, half, 0.03f, z + 0.08f, z + 1.05f, label, refl));
      }
    }
  }
  // A back wing of another height makes footprints and roof lines irregular.
  if (rng.bernoulli(0.4) && depth > 12.0f) {
    const float ws = static_cast<float>(rng.uniform(0.3, 0.7)) * width;
    const float wd = static_cast<float>(rng.uniform(4.0, 9.0));
    const float hs = height * static_cast<float>(rng.uniform(0.5, 1.3));
    const float ss = s0 + static_cast<float>(rng.uniform(0.0, width - ws));
    obj.parts.push_back(
        side_box(side, ss + 0.5f * ws, o0 + depth + 0.5f * wd - 0.5f, 0.5f * ws, 0.5f * wd, z0, z0 + hs, label, refl));
  }
  return obj;
}

WorldObject make_tree(PartBuilder& b, const Vector2f& p, float scale) {
  Rng& rng = b.rng;
  const float z = b.ground(p);
  const float trunk_h = scale * static_cast<float>(rng.uniform(1.8, 3.4));
  const float trunk_r = scale * static_cast<float>(rng.uniform(0.12, 0.3));
  WorldObject obj = start_object(ObjectKind::kTree, b.instance, p, {0, 0}, 0.0f, 0.0f);
  obj.parts.push_back(Primitive::cylinder(lift(p, z - 0.2f), trunk_r, trunk_h + 1.0f,
                                          encode_label(semantic::kTrunk, b.instance), 0.35f));
  obj.height_m = trunk_h;  // regrow_crown reads the trunk height from here
  regrow_crown(obj, rng);
  return obj;
}

void regrow_crown(WorldObject& tree, Rng& rng) {
  tree.parts.resize(1);  // keep the trunk
  const Primitive& trunk = tree.parts[0];
  const Vector3f base = trunk.a;
  const float trunk_h = trunk.b.z() - 1.0f + 0.2f;
  const uint32_t label = encode_label(semantic::kVegetation, tree.instance);
  // Species: round, columnar or spreading crowns of 3..6 overlapping ellipsoids.
  const int species = static_cast<int>(rng.index(3));
  const float r = static_cast<float>(rng.uniform(1.3, 3.0));
  const float rz = species == 1 ? 2.0f * r : (species == 2 ? 0.6f * r : r);
  const float rx = species == 2 ? 1.4f * r : r;
  const int lobes = rng.uniform_int(3, 6);
  const Vector3f centre = base + Vector3f(0, 0, trunk_h + 0.2f + 0.8f * rz);
  for (int i = 0; i < lobes; ++i) {
    const Vector3f offset(static_cast<float>(rng.uniform(-0.5, 0.5)) * rx,
                          static_cast<float>(rng.uniform(-0.5, 0.5)) * rx,
                          static_cast<float>(rng.uniform(-0.3, 0.4)) * rz);
    const float k = static_cast<float>(rng.uniform(0.55, 0.85));
    tree.parts.push_back(Primitive::ellipsoid(
        centre + offset, {k * rx, k * rx * static_cast<float>(rng.uniform(0.8, 1.2)), k * rz}, label, 0.45f));
  }
  tree.half_extents = {rx, rx};
  tree.height_m = centre.z() + rz - base.z();
}

WorldObject make_bush(PartBuilder& b, const Vector2f& p) {
  Rng& rng = b.rng;
  const float z = b.ground(p);
  const uint32_t label = encode_label(semantic::kVegetation, b.instance);
  WorldObject obj = start_object(ObjectKind::kBush, b.instance, p, {0.8f, 0.8f}, 0.0f, 1.0f);
  const int lobes = rng.uniform_int(1, 3);
  for (int i = 0; i < lobes; ++i) {
    const float r = static_cast<float>(rng.uniform(0.4, 0.9));
    const Vector2f q =
        p + Vector2f(static_cast<float>(rng.uniform(-0.6, 0.6)), static_cast<float>(rng.uniform(-0.6, 0.6)));
    obj.parts.push_back(Primitive::ellipsoid(lift(q, z + 0.6f * r), {r, r, 0.8f * r}, label, 0.45f));
  }
  return obj;
}

WorldObject make_hedge(PartBuilder& b, const SideFrame& side, float s0, float s1, float o) {
  Rng& rng = b.rng;
  const uint32_t label = encode_label(semantic::kVegetation, b.instance);
  WorldObject obj = start_object(ObjectKind::kHedge, b.instance, side.at(0.5f * (s0 + s1), o), {0.5f * (s1 - s0), 0.5f},
                                 side.yaw(), 1.5f);
  const float h = static_cast<float>(rng.uniform(0.9, 1.8));
  // Irregular top and thickness: short pieces of slightly different size.
  for (float s = s0; s < s1 - 0.5f;) {
    const float len = std::min(s1 - s, static_cast<float>(rng.uniform(1.5, 3.5)));
    const float z = b.ground(side.at(s + 0.5f * len, o));
    const float hh = h + static_cast<float>(rng.uniform(-0.15, 0.15));
    const float th = static_cast<float>(rng.uniform(0.35, 0.55));
    obj.parts.push_back(side_box(side, s + 0.5f * len, o, 0.5f * len + 0.1f, th, z - 0.2f, z + hh, label, 0.45f));
    s += len;
  }
  return obj;
}

WorldObject make_wall(PartBuilder& b, const SideFrame& side, float s0, float s1, float o) {
  const uint32_t label = encode_label(semantic::kOtherStructure, b.instance);
  const float h = static_cast<float>(b.rng.uniform(0.8, 2.4));
  const float z = std::min(b.ground(side.at(s0, o)), b.ground(side.at(s1, o)));
  WorldObject obj = start_object(ObjectKind::kWall, b.instance, side.at(0.5f * (s0 + s1), o), {0.5f * (s1 - s0), 0.15f},
                                 side.yaw(), h);
  obj.parts.push_back(side_box(side, 0.5f * (s0 + s1), o, 0.5f * (s1 - s0), 0.15f, z - 0.3f, z + h, label, 0.6f));
  return obj;
}

WorldObject make_fence(PartBuilder& b, const SideFrame& side, float s0, float s1, float o) {
  const uint32_t label = encode_label(semantic::kFence, b.instance);
  const float h = static_cast<float>(b.rng.uniform(1.0, 1.8));
  const float spacing = static_cast<float>(b.rng.uniform(2.0, 3.0));
  WorldObject obj = start_object(ObjectKind::kFence, b.instance, side.at(0.5f * (s0 + s1), o),
                                 {0.5f * (s1 - s0), 0.05f}, side.yaw(), h);
  const float z = b.ground(side.at(0.5f * (s0 + s1), o));
  for (float s = s0; s <= s1 + 1e-3f; s += spacing) {
    const float zp = b.ground(side.at(s, o));
    obj.parts.push_back(side_box(side, s, o, 0.05f, 0.05f, zp - 0.2f, zp + h, label, 0.7f));
  }
  for (float frac : {0.35f, 0.9f}) {
    obj.parts.push_back(side_box(side, 0.5f * (s0 + s1), o, 0.5f * (s1 - s0), 0.02f, z + frac * h - 0.06f,
                                 z + frac * h + 0.06f, label, 0.7f));
  }
  return obj;
}

WorldObject make_street_lamp(PartBuilder& b, const Vector2f& p, float yaw_to_road, float height) {
  const uint32_t label = encode_label(semantic::kPole, b.instance);
  const float z = b.ground(p);
  WorldObject obj = start_object(ObjectKind::kStreetLamp, b.instance, p, {0.15f, 0.15f}, yaw_to_road, height);
  obj.parts.push_back(Primitive::cylinder(lift(p, z - 0.2f), 0.11f, height + 0.2f, label, 0.8f));
  obj.parts.push_back(Primitive::cylinder(lift(p, z - 0.2f), 0.2f, 0.9f, label, 0.8f));  // foot
  const Vector2f dir(std::cos(yaw_to_road), std::sin(yaw_to_road));
  const float arm = 1.6f;
  obj.parts.push_back(Primitive::box(lift(p + 0.5f * arm * dir, z + height - 0.1f), {0.5f * arm, 0.05f, 0.05f},
                                     yaw_to_road, label, 0.8f));
  obj.parts.push_back(
      Primitive::box(lift(p + arm * dir, z + height - 0.25f), {0.35f, 0.15f, 0.1f}, yaw_to_road, label, 0.9f));
  return obj;
}

WorldObject make_pole(PartBuilder& b, const Vector2f& p) {
  const uint32_t label = encode_label(semantic::kPole, b.instance);
  const float z = b.ground(p);
  const float h = static_cast<float>(b.rng.uniform(3.0, 9.5));
  const float r = static_cast<float>(b.rng.uniform(0.06, 0.16));
  WorldObject obj = start_object(ObjectKind::kPole, b.instance, p, {r, r}, 0.0f, h);
  obj.parts.push_back(Primitive::cylinder(lift(p, z - 0.2f), r, h + 0.2f, label, 0.6f));
  if (h > 7.0f && b.rng.bernoulli(0.5)) {  // utility pole cross-arm
    obj.parts.push_back(Primitive::box(lift(p, z + h - 0.5f), {0.9f, 0.06f, 0.06f},
                                       static_cast<float>(b.rng.uniform(0, M_PI)), label, 0.6f));
  }
  return obj;
}

WorldObject make_sign(PartBuilder& b, const Vector2f& p, float yaw_to_road) {
  const float z = b.ground(p);
  const float h = static_cast<float>(b.rng.uniform(2.0, 3.0));
  WorldObject obj = start_object(ObjectKind::kSign, b.instance, p, {0.4f, 0.1f}, yaw_to_road, h);
  obj.parts.push_back(
      Primitive::cylinder(lift(p, z - 0.2f), 0.04f, h + 0.2f, encode_label(semantic::kPole, b.instance), 0.6f));
  const float w = static_cast<float>(b.rng.uniform(0.5, 0.9));
  const float ph = static_cast<float>(b.rng.uniform(0.5, 0.9));
  // The plate faces the road: its thin axis points along yaw_to_road.
  obj.parts.push_back(Primitive::box(lift(p, z + h - 0.5f * ph), {0.03f, 0.5f * w, 0.5f * ph}, yaw_to_road,
                                     encode_label(semantic::kTrafficSign, b.instance), 0.95f));
  return obj;
}

WorldObject make_bench(PartBuilder& b, const Vector2f& p, float yaw) {
  const uint32_t label = encode_label(semantic::kOtherObject, b.instance);
  const float z = b.ground(p);
  WorldObject obj = start_object(ObjectKind::kBench, b.instance, p, {0.9f, 0.3f}, yaw, 0.9f);
  obj.parts.push_back(Primitive::box(lift(p, z + 0.225f), {0.9f, 0.25f, 0.225f}, yaw, label, 0.5f));
  const Vector2f back = p + 0.25f * Vector2f(-std::sin(yaw), std::cos(yaw));
  obj.parts.push_back(Primitive::box(lift(back, z + 0.65f), {0.9f, 0.04f, 0.25f}, yaw, label, 0.5f));
  return obj;
}

WorldObject make_car(PartBuilder& b, const Vector2f& p, float yaw, int model) {
  // length, width, body top, roof height, cabin length fraction
  static const float kModel[kCarModels][4] = {{1.65f, 0.95f, 1.45f, 0.55f},
                                              {1.75f, 1.0f, 1.45f, 0.6f},
                                              {1.8f, 1.0f, 1.45f, 0.55f},
                                              {1.9f, 1.05f, 1.75f, 0.6f},
                                              {2.0f, 1.2f, 2.2f, 0.85f}};
  const float* m = kModel[model % kCarModels];
  const float len = car_length(model), wid = m[0], body_top = m[1], roof = m[2], cabin = m[3];
  const uint32_t label = encode_label(semantic::kCar, b.instance);
  const float refl = static_cast<float>(b.rng.uniform(0.2, 0.9));
  const float z = b.ground(p);
  WorldObject obj = start_object(ObjectKind::kCar, b.instance, p, {0.5f * len, 0.5f * wid}, yaw, roof);
  const Vector2f fwd(std::cos(yaw), std::sin(yaw));
  obj.parts.push_back(Primitive::box(lift(p, z + 0.5f * (0.3f + body_top)),
                                     {0.5f * len, 0.5f * wid, 0.5f * (body_top - 0.3f)}, yaw, label, refl));
  const Vector2f cabin_c = p - 0.08f * len * fwd;
  obj.parts.push_back(Primitive::box(lift(cabin_c, z + 0.5f * (body_top + roof)),
                                     {0.5f * cabin * len, 0.5f * wid - 0.08f, 0.5f * (roof - body_top)}, yaw, label,
                                     0.3f));
  const Vector2f side(-fwd.y(), fwd.x());
  for (float fs : {-0.33f, 0.33f})
    for (float ss : {-0.45f, 0.45f}) {
      const Vector2f w = p + fs * len * fwd + ss * wid * side;
      obj.parts.push_back(Primitive::box(lift(w, z + 0.32f), {0.32f, 0.1f, 0.32f}, yaw, label, 0.1f));
    }
  return obj;
}

WorldObject make_pedestrian(PartBuilder& b, const Vector2f& p) {
  const uint32_t label = encode_label(semantic::kPerson, b.instance);
  const float z = b.ground(p);
  const float h = static_cast<float>(b.rng.uniform(1.55, 1.9));
  const float yaw = static_cast<float>(b.rng.uniform(0, 2 * M_PI));
  WorldObject obj = start_object(ObjectKind::kPedestrian, b.instance, p, {0.25f, 0.2f}, yaw, h);
  obj.parts.push_back(Primitive::box(lift(p, z + 0.22f * h), {0.12f, 0.18f, 0.22f * h}, yaw, label, 0.4f));
  obj.parts.push_back(Primitive::cylinder(lift(p, z + 0.44f * h), 0.2f, 0.42f * h, label, 0.4f));
  obj.parts.push_back(Primitive::ellipsoid(lift(p, z + 0.93f * h), {0.1f, 0.1f, 0.07f * h}, label, 0.4f));
  return obj;
}

}  // namespace segmatch::sim::detail
