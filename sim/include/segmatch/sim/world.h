// Generated urban worlds: a street grid with blocks, terrain with gentle slopes and kerbs,
// buildings with facade relief, street furniture, vegetation and parked cars. Every object
// has a SemanticKITTI class and a unique instance id, so simulated returns are labelled with
// the object they hit and true segment matches can be derived later.
#pragma once

#include "segmatch/sim/scene.h"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "segmatch/core/common/types.h"

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch::sim {

// SemanticKITTI class ids used by the simulator.
namespace semantic {
constexpr uint16_t kCar = 10;
constexpr uint16_t kPerson = 30;
constexpr uint16_t kRoad = 40;
constexpr uint16_t kSidewalk = 48;
constexpr uint16_t kBuilding = 50;
constexpr uint16_t kFence = 51;
constexpr uint16_t kOtherStructure = 52;
constexpr uint16_t kVegetation = 70;
constexpr uint16_t kTrunk = 71;
constexpr uint16_t kTerrain = 72;
constexpr uint16_t kPole = 80;
constexpr uint16_t kTrafficSign = 81;
constexpr uint16_t kOtherObject = 99;
}  // namespace semantic

enum class ObjectKind : uint8_t {
  kBuilding,
  kStreetLamp,
  kPole,
  kSign,
  kTree,
  kBush,
  kHedge,
  kWall,
  kFence,
  kCar,
  kPedestrian,
  kBench,
};
const char* to_string(ObjectKind kind);

struct WorldObject {
  ObjectKind kind = ObjectKind::kBuilding;
  uint16_t instance = 0;                                   // unique in the world, 0 = ground
  Eigen::Vector2f position = Eigen::Vector2f::Zero();      // footprint centre (m)
  Eigen::Vector2f half_extents = Eigen::Vector2f::Zero();  // footprint half size (m)
  float yaw = 0.0f;                                        // footprint orientation (rad)
  float height_m = 0.0f;
  std::vector<Primitive> parts;  // geometry in world coordinates
};

// Street graph: nodes are intersections, edges are street segments between them.
struct StreetGraph {
  struct Edge {
    int a = 0, b = 0;
    int lanes_per_direction = 1;
    float width_m = 12.0f;  // kerb to kerb
  };
  std::vector<Eigen::Vector2d> nodes;
  std::vector<Edge> edges;
  std::vector<std::vector<int>> node_edges;  // edge indices incident to each node

  int other_end(int edge, int node) const { return edges[edge].a == node ? edges[edge].b : edges[edge].a; }
  double edge_length(int edge) const { return (nodes[edges[edge].a] - nodes[edges[edge].b]).norm(); }
  double total_length_m() const;
};

// Street centre lines of the grid: vertical lines at x[i] (width x_width[i], kerb to kerb)
// and horizontal lines at y[j]. Streets run through the whole world, out to its bounds.
struct GridLayout {
  std::vector<double> x, x_width, y, y_width;
  std::vector<int> x_lanes, y_lanes;  // lanes per direction of each line
};

// Gentle rolling terrain: a plane plus two long sinusoids, with the grade bounded.
struct Terrain {
  double grade_x = 0, grade_y = 0;
  double amp1 = 0, wavelength1 = 300, phase1 = 0;
  double amp2 = 0, wavelength2 = 300, phase2 = 0;
  double height(double x, double y) const;
};

struct WorldConfig {
  uint64_t seed = 1;
  int blocks_x = 4;  // street grid size in blocks
  int blocks_y = 4;
  float block_min_m = 70.0f;  // block size range (kerb to kerb distance between streets)
  float block_max_m = 120.0f;
  float lane_width_m = 3.5f;
  float parking_lane_width_m = 2.3f;
  float sidewalk_width_m = 3.0f;
  float kerb_height_m = 0.15f;
  float max_grade = 0.04f;             // terrain slope bound (rise over run)
  float wide_street_fraction = 0.25f;  // streets with two lanes per direction
  float park_block_fraction = 0.15f;   // blocks that are parks instead of buildings
  float parked_car_fill = 0.55f;       // fraction of parking length occupied
  float tree_street_fraction = 0.5f;   // street sides lined with regularly spaced trees
  float ground_cell_m = 5.0f;          // ground mesh resolution

  void validate() const;  // throws std::invalid_argument naming the bad field
};

struct World {
  WorldConfig config;
  GridLayout grid;
  Terrain terrain;
  StreetGraph streets;
  Eigen::AlignedBox2d bounds;
  std::vector<Primitive> ground;  // terrain, roads, sidewalks and kerbs
  std::vector<WorldObject> objects;
  uint16_t next_instance = 1;

  // Terrain height (m) of the road surface at (x, y); sidewalks and blocks sit a kerb higher.
  double road_height(double x, double y) const;
  // Surface height at (x, y) including the kerb step on sidewalks and blocks.
  double surface_height(double x, double y) const;
  bool on_road(double x, double y) const;
  // All primitives: ground plus every object's parts.
  Scene scene() const;
  size_t count(ObjectKind kind) const;
  // Hands out the next free instance id; throws std::runtime_error past 65535 objects.
  uint16_t allocate_instance();
};

World generate_world(const WorldConfig& config);

// How the world differs when it is driven again (for the second traversal).
struct ChangeConfig {
  uint64_t seed = 2;
  float car_removed_fraction = 0.3f;
  float car_moved_fraction = 0.2f;
  float new_car_fill = 0.25f;                 // fraction of free parking length filled with new cars
  float pedestrians_per_100m = 1.5f;          // per 100 m of street
  float vegetation_changed_fraction = 0.15f;  // bushes removed/added, tree crowns regrown
};

// Returns the changed world. Objects that moved or were replaced get new instance ids;
// unchanged objects keep theirs, so a segment of one traversal can be matched to the other.
World change_world(const World& world, const ChangeConfig& config);

}  // namespace segmatch::sim
