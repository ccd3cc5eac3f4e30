// Private builders of object geometry for the world generator (world_objects.cpp).
#pragma once

#include "segmatch/core/detail/random.h"
#include "segmatch/sim/world.h"

#include <Eigen/Core>

namespace segmatch::sim::detail {

// A street side seen from the road: origin at the kerb, `along` runs with the street,
// `inward` points from the kerb into the block. Local coordinates (s, o) map to
// origin + s * along + o * inward.
struct SideFrame {
  Eigen::Vector2f origin;
  Eigen::Vector2f along;
  Eigen::Vector2f inward;
  float length_m = 0.0f;
  uint64_t street_key = 0;  // identifies the street line, so both sides share a style

  Eigen::Vector2f at(float s, float o) const { return origin + s * along + o * inward; }
  float yaw() const;
};

struct PartBuilder {
  const World& world;
  Rng& rng;
  uint16_t instance;

  float ground(const Eigen::Vector2f& p) const { return static_cast<float>(world.surface_height(p.x(), p.y())); }
};

// Buildings: footprint w x d on a side at (s, o) (front-left corner along the side).
WorldObject make_building(PartBuilder& b, const SideFrame& side, float s0, float o0, float width, float depth,
                          float height);
WorldObject make_tree(PartBuilder& b, const Eigen::Vector2f& p, float scale);
WorldObject make_bush(PartBuilder& b, const Eigen::Vector2f& p);
WorldObject make_hedge(PartBuilder& b, const SideFrame& side, float s0, float s1, float o);
WorldObject make_wall(PartBuilder& b, const SideFrame& side, float s0, float s1, float o);
WorldObject make_fence(PartBuilder& b, const SideFrame& side, float s0, float s1, float o);
WorldObject make_street_lamp(PartBuilder& b, const Eigen::Vector2f& p, float yaw_to_road, float height);
WorldObject make_pole(PartBuilder& b, const Eigen::Vector2f& p);
WorldObject make_sign(PartBuilder& b, const Eigen::Vector2f& p, float yaw_to_road);
WorldObject make_bench(PartBuilder& b, const Eigen::Vector2f& p, float yaw);
// Cars: `length`-long footprint centred at p, heading yaw.
WorldObject make_car(PartBuilder& b, const Eigen::Vector2f& p, float yaw, int model);
WorldObject make_pedestrian(PartBuilder& b, const Eigen::Vector2f& p);
// Regrows a tree's crown with a new random shape (same trunk, same instance).
void regrow_crown(WorldObject& tree, Rng& rng);

constexpr int kCarModels = 5;
float car_length(int model);

}  // namespace segmatch::sim::detail
