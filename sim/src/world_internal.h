// Private pieces of the world generator shared by world.cpp, world_placement.cpp and
// world_changes.cpp.
#pragma once

#include "segmatch/core/detail/random.h"
#include "segmatch/sim/world.h"
#include "world_parts.h"

#include <Eigen/Geometry>

#include <array>
#include <vector>

namespace segmatch::sim::detail {

enum Side { kLeft = 0, kRight = 1, kBottom = 2, kTop = 3 };

// A block: the area between four street lines (or a street line and the world's edge).
struct Block {
  Eigen::AlignedBox2d box;        // kerb to kerb
  std::array<bool, 4> street{};   // which sides face a street (by Side)
  std::array<int, 4> line_ids{};  // grid line index of each side (left, right, bottom, top)
  bool outer = false;             // in the ring beyond the outermost streets
};

std::vector<Block> make_blocks(const World& w);
std::vector<SideFrame> block_sides(const World& w, const Block& b);
void build_road_mesh(World& w);
void build_block_ground(World& w, const Block& b);
void populate_block(World& w, const Block& b, Rng& rng);
void park_cars(World& w, Rng& rng);
// Places cars along the parking lanes; `fill` is the fraction of free length to occupy.
// Existing cars in `w` are respected (no overlap).
void fill_parking(World& w, Rng& rng, float fill);

}  // namespace segmatch::sim::detail
