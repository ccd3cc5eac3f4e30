#include "segmatch/sim/world.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <set>

using namespace segmatch;
using namespace segmatch::sim;

namespace {

WorldConfig demo_like(uint64_t seed) {
  WorldConfig c;
  c.seed = seed;
  c.blocks_x = 4;
  c.blocks_y = 3;
  return c;
}

bool same_primitive(const Primitive& a, const Primitive& b) {
  return a.shape == b.shape && a.a == b.a && a.b == b.b && a.c == b.c && a.yaw == b.yaw && a.label == b.label &&
         a.reflectivity == b.reflectivity;
}

bool same_scene(const Scene& a, const Scene& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (!same_primitive(a[i], b[i])) return false;
  return true;
}

}  // namespace

TEST(World, SameSeedGivesSameWorldOtherSeedDiffers) {
  const World a = generate_world(demo_like(7));
  const World b = generate_world(demo_like(7));
  const World c = generate_world(demo_like(8));
  EXPECT_TRUE(same_scene(a.scene(), b.scene()));
  EXPECT_FALSE(same_scene(a.scene(), c.scene()));
}

TEST(World, HasEveryKindOfObjectOfAUrbanStreet) {
  const World w = generate_world(demo_like(1));
  for (ObjectKind k : {ObjectKind::kBuilding, ObjectKind::kStreetLamp, ObjectKind::kPole, ObjectKind::kSign,
                       ObjectKind::kTree, ObjectKind::kBush, ObjectKind::kCar, ObjectKind::kBench}) {
    EXPECT_GT(w.count(k), 3u) << to_string(k);
  }
  EXPECT_GT(w.count(ObjectKind::kHedge) + w.count(ObjectKind::kWall) + w.count(ObjectKind::kFence), 10u);
  EXPECT_EQ(w.count(ObjectKind::kPedestrian), 0u) << "pedestrians only appear in a changed world";
  EXPECT_GT(w.count(ObjectKind::kBuilding), 40u);
  EXPECT_GT(w.count(ObjectKind::kCar), 100u);
  EXPECT_GT(w.streets.total_length_m(), 2000.0);
}

TEST(World, RepeatedObjectsExistAsInARealCity) {
  // Lamps of one street share a design: many lamps have exactly the same height, so a lamp
  // alone is not distinctive, only its context is.
  const World w = generate_world(demo_like(1));
  std::map<float, int> lamp_heights;
  for (const auto& o : w.objects)
    if (o.kind == ObjectKind::kStreetLamp) ++lamp_heights[o.height_m];
  int largest_family = 0;
  for (const auto& [h, n] : lamp_heights) largest_family = std::max(largest_family, n);
  EXPECT_GE(largest_family, 6);
}

TEST(World, InstanceIdsAreUniqueAndLabelEveryPart) {
  const World w = generate_world(demo_like(3));
  std::set<uint16_t> ids;
  for (const auto& o : w.objects) {
    EXPECT_NE(o.instance, 0);
    EXPECT_TRUE(ids.insert(o.instance).second) << "duplicate instance " << o.instance;
    ASSERT_FALSE(o.parts.empty()) << to_string(o.kind);
    for (const auto& p : o.parts) EXPECT_EQ(label_instance(p.label), o.instance);
  }
  for (const auto& p : w.ground) EXPECT_EQ(label_instance(p.label), 0);
}

TEST(World, BuildingsHaveFacadeRelief) {
  const World w = generate_world(demo_like(1));
  size_t detailed = 0, buildings = 0;
  for (const auto& o : w.objects) {
    if (o.kind != ObjectKind::kBuilding) continue;
    ++buildings;
    detailed += o.parts.size() >= 6;
  }
  EXPECT_GT(detailed, buildings * 9 / 10);
}

TEST(World, TerrainSlopeIsGentleAndBounded) {
  WorldConfig c = demo_like(5);
  c.max_grade = 0.04f;
  const World w = generate_world(c);
  double steepest = 0;
  for (double x = w.bounds.min().x(); x < w.bounds.max().x(); x += 7.0)
    for (double y = w.bounds.min().y(); y < w.bounds.max().y(); y += 7.0) {
      const double gx = (w.road_height(x + 0.5, y) - w.road_height(x - 0.5, y));
      const double gy = (w.road_height(x, y + 0.5) - w.road_height(x, y - 0.5));
      steepest = std::max(steepest, std::hypot(gx, gy));
    }
  EXPECT_LE(steepest, c.max_grade + 1e-6);
  EXPECT_GT(steepest, 0.002) << "terrain should not be flat";
}

TEST(World, KerbRaisesSidewalksAboveTheRoad) {
  const World w = generate_world(demo_like(1));
  const double x = w.grid.x[1], y = 0.5 * (w.grid.y[0] + w.grid.y[1]);
  ASSERT_TRUE(w.on_road(x, y));
  const double kerb_x = x + 0.5 * w.grid.x_width[1] + 1.0;  // 1 m onto the sidewalk
  ASSERT_FALSE(w.on_road(kerb_x, y));
  EXPECT_NEAR(w.surface_height(kerb_x, y) - w.road_height(kerb_x, y), w.config.kerb_height_m, 1e-9);
  EXPECT_NEAR(w.surface_height(x, y), w.road_height(x, y), 1e-12);
}

TEST(World, OnlyCarsStandOnTheRoad) {
  const World w = generate_world(demo_like(2));
  for (const auto& o : w.objects) {
    const bool road = w.on_road(o.position.x(), o.position.y());
    if (o.kind == ObjectKind::kCar) {
      EXPECT_TRUE(road) << "car " << o.instance;
    } else {
      EXPECT_FALSE(road) << to_string(o.kind) << " " << o.instance << " on the road";
    }
  }
}

TEST(World, InvalidConfigIsRefusedWithTheFieldName) {
  WorldConfig c;
  c.blocks_x = 0;
  try {
    generate_world(c);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("blocks_x"), std::string::npos) << e.what();
  }
}

TEST(WorldChange, CarsComeAndGoPedestriansAppearStaticObjectsStay) {
  const World before = generate_world(demo_like(4));
  const World after = change_world(before, ChangeConfig{});
  std::map<uint16_t, const WorldObject*> old;
  for (const auto& o : before.objects) old[o.instance] = &o;
  size_t cars_kept = 0, cars_new = 0, crowns_changed = 0, static_same = 0, static_total = 0;
  std::set<uint16_t> seen;
  for (const auto& o : after.objects) {
    seen.insert(o.instance);
    auto it = old.find(o.instance);
    if (o.kind == ObjectKind::kCar) {
      (it == old.end() ? cars_new : cars_kept)++;
    } else if (o.kind == ObjectKind::kBuilding || o.kind == ObjectKind::kStreetLamp || o.kind == ObjectKind::kPole) {
      ++static_total;
      ASSERT_NE(it, old.end()) << "static object lost its instance id";
      static_same += same_scene(o.parts, it->second->parts);
    } else if (o.kind == ObjectKind::kTree && it != old.end()) {
      crowns_changed += !same_scene(o.parts, it->second->parts);
    }
  }
  size_t cars_gone = 0;
  for (const auto& o : before.objects) cars_gone += o.kind == ObjectKind::kCar && !seen.count(o.instance);
  EXPECT_EQ(static_same, static_total) << "buildings, lamps and poles must not change";
  EXPECT_GT(cars_kept, before.count(ObjectKind::kCar) / 3);
  EXPECT_GT(cars_gone, before.count(ObjectKind::kCar) / 5);
  EXPECT_GT(cars_new, 20u);
  EXPECT_GT(after.count(ObjectKind::kPedestrian), 10u);
  EXPECT_GT(crowns_changed, 5u);
}
