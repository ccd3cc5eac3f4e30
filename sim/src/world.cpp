// World layout: street grid, terrain, and the ground surface (roads, kerbs, sidewalks).
#include "segmatch/sim/world.h"

#include "segmatch/core/detail/random.h"
#include "world_internal.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace segmatch::sim {

const char* to_string(ObjectKind kind) {
  switch (kind) {
    case ObjectKind::kBuilding: return "building";
    case ObjectKind::kStreetLamp: return "street_lamp";
    case ObjectKind::kPole: return "pole";
    case ObjectKind::kSign: return "sign";
    case ObjectKind::kTree: return "tree";
    case ObjectKind::kBush: return "bush";
    case ObjectKind::kHedge: return "hedge";
    case ObjectKind::kWall: return "wall";
    case ObjectKind::kFence: return "fence";
    case ObjectKind::kCar: return "car";
    case ObjectKind::kPedestrian: return "pedestrian";
    case ObjectKind::kBench: return "bench";
  }
  return "unknown";
}

double StreetGraph::total_length_m() const {
  double sum = 0;
  for (size_t e = 0; e < edges.size(); ++e) sum += edge_length(static_cast<int>(e));
  return sum;
}

void WorldConfig::validate() const {
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw std::invalid_argument("invalid world config: " + what);
  };
  require(blocks_x >= 1 && blocks_x <= 60, "blocks_x must be in 1..60");
  require(blocks_y >= 1 && blocks_y <= 60, "blocks_y must be in 1..60");
  require(block_min_m >= 30.0f && block_max_m >= block_min_m && block_max_m <= 400.0f,
          "block size range must satisfy 30 <= block_min_m <= block_max_m <= 400");
  require(lane_width_m >= 2.5f && lane_width_m <= 5.0f, "lane_width_m must be in 2.5..5");
  require(sidewalk_width_m >= 1.0f && sidewalk_width_m <= 8.0f, "sidewalk_width_m must be in 1..8");
  require(kerb_height_m >= 0.0f && kerb_height_m <= 0.4f, "kerb_height_m must be in 0..0.4");
  require(max_grade >= 0.0f && max_grade <= 0.12f, "max_grade must be in 0..0.12");
  require(ground_cell_m >= 1.0f && ground_cell_m <= 20.0f, "ground_cell_m must be in 1..20");
  for (float f : {wide_street_fraction, park_block_fraction, parked_car_fill, tree_street_fraction})
    require(f >= 0.0f && f <= 1.0f, "fractions must be in 0..1");
}

double Terrain::height(double x, double y) const {
  constexpr double kTwoPi = 6.283185307179586;
  return grade_x * x + grade_y * y + amp1 * std::sin(kTwoPi * x / wavelength1 + phase1) +
         amp2 * std::sin(kTwoPi * y / wavelength2 + phase2);
}

double World::road_height(double x, double y) const { return terrain.height(x, y); }

bool World::on_road(double x, double y) const {
  for (size_t i = 0; i < grid.x.size(); ++i)
    if (std::abs(x - grid.x[i]) <= 0.5 * grid.x_width[i]) return true;
  for (size_t j = 0; j < grid.y.size(); ++j)
    if (std::abs(y - grid.y[j]) <= 0.5 * grid.y_width[j]) return true;
  return false;
}

double World::surface_height(double x, double y) const {
  return road_height(x, y) + (on_road(x, y) ? 0.0 : config.kerb_height_m);
}

Scene World::scene() const {
  Scene scene = ground;
  size_t n = scene.size();
  for (const auto& o : objects) n += o.parts.size();
  scene.reserve(n);
  for (const auto& o : objects) scene.insert(scene.end(), o.parts.begin(), o.parts.end());
  return scene;
}

size_t World::count(ObjectKind kind) const {
  return static_cast<size_t>(
      std::count_if(objects.begin(), objects.end(), [kind](const WorldObject& o) { return o.kind == kind; }));
}

uint16_t World::allocate_instance() {
  if (next_instance == 0xFFFF)
    throw std::runtime_error("world too large: more than 65534 objects (SemanticKITTI instance ids are 16 bit)");
  return next_instance++;
}

namespace detail {
namespace {

// Street lines along one axis: centre positions and widths, blocks of random size between.
void layout_lines(const WorldConfig& c, Rng& rng, int blocks, std::vector<double>& pos, std::vector<double>& width,
                  std::vector<int>& lanes) {
  for (int i = 0; i <= blocks; ++i) {
    const int l = rng.bernoulli(c.wide_street_fraction) ? 2 : 1;
    lanes.push_back(l);
    width.push_back(2.0 * l * c.lane_width_m + 2.0 * c.parking_lane_width_m);
  }
  pos.push_back(0.0);
  for (int i = 0; i < blocks; ++i) {
    const double block = rng.uniform(c.block_min_m, c.block_max_m);
    pos.push_back(pos.back() + 0.5 * width[i] + block + 0.5 * width[i + 1]);
  }
}

void build_graph(World& w) {
  const auto& g = w.grid;
  const int nx = static_cast<int>(g.x.size()), ny = static_cast<int>(g.y.size());
  auto id = [nx](int i, int j) { return j * nx + i; };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) w.streets.nodes.emplace_back(g.x[i], g.y[j]);
  w.streets.node_edges.assign(w.streets.nodes.size(), {});
  auto add = [&](int a, int b, int lanes, double width) {
    w.streets.node_edges[a].push_back(static_cast<int>(w.streets.edges.size()));
    w.streets.node_edges[b].push_back(static_cast<int>(w.streets.edges.size()));
    w.streets.edges.push_back({a, b, lanes, static_cast<float>(width)});
  };
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) add(id(i, j), id(i + 1, j), g.y_lanes[j], g.y_width[j]);
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j + 1 < ny; ++j) add(id(i, j), id(i, j + 1), g.x_lanes[i], g.x_width[i]);
}

void add_quad(std::vector<Primitive>& out, const Eigen::Vector3f& p00, const Eigen::Vector3f& p10,
              const Eigen::Vector3f& p11, const Eigen::Vector3f& p01, uint32_t label, float refl) {
  out.push_back(Primitive::triangle(p00, p10, p11, label, refl));
  out.push_back(Primitive::triangle(p00, p11, p01, label, refl));
}

// Grid coordinates from a to b with the given breaks kept and steps of at most `cell`.
std::vector<double> subdivide(double a, double b, std::vector<double> breaks, double cell) {
  breaks.push_back(a);
  breaks.push_back(b);
  std::sort(breaks.begin(), breaks.end());
  std::vector<double> out;
  for (size_t k = 0; k + 1 < breaks.size(); ++k) {
    const double lo = breaks[k], hi = breaks[k + 1];
    if (hi - lo < 1e-6) continue;
    const int n = std::max(1, static_cast<int>(std::ceil((hi - lo) / cell)));
    for (int s = 0; s < n; ++s) out.push_back(lo + (hi - lo) * s / n);
  }
  out.push_back(b);
  return out;
}

}  // namespace

void build_road_mesh(World& w) {
  const double cell = w.config.ground_cell_m;
  const auto& b = w.bounds;
  const int nx = static_cast<int>(std::ceil(b.sizes().x() / cell));
  const int ny = static_cast<int>(std::ceil(b.sizes().y() / cell));
  const uint32_t label = encode_label(semantic::kRoad, 0);
  auto vertex = [&](int i, int j) {
    const double x = b.min().x() + i * cell, y = b.min().y() + j * cell;
    return Eigen::Vector3f(float(x), float(y), float(w.road_height(x, y)));
  };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const Eigen::Vector3f p00 = vertex(i, j), p10 = vertex(i + 1, j), p11 = vertex(i + 1, j + 1),
                            p01 = vertex(i, j + 1);
      // Cells with no road corner lie wholly under a block (roads are wider than a cell).
      bool road = false;
      for (const Eigen::Vector3f& p : {p00, p10, p11, p01}) road |= w.on_road(p.x(), p.y());
      if (road) add_quad(w.ground, p00, p10, p11, p01, label, 0.25f);
    }
  }
}

void build_block_ground(World& w, const Block& blk) {
  const double cell = w.config.ground_cell_m, sw = w.config.sidewalk_width_m;
  const float kerb = w.config.kerb_height_m;
  const double swl = blk.street[kLeft] ? sw : 0, swr = blk.street[kRight] ? sw : 0;
  const double swb = blk.street[kBottom] ? sw : 0, swt = blk.street[kTop] ? sw : 0;
  const auto xs =
      subdivide(blk.box.min().x(), blk.box.max().x(), {blk.box.min().x() + swl, blk.box.max().x() - swr}, cell);
  const auto ys =
      subdivide(blk.box.min().y(), blk.box.max().y(), {blk.box.min().y() + swb, blk.box.max().y() - swt}, cell);
  auto vertex = [&](double x, double y) {
    return Eigen::Vector3f(float(x), float(y), float(w.road_height(x, y)) + kerb);
  };
  for (size_t j = 0; j + 1 < ys.size(); ++j) {
    for (size_t i = 0; i + 1 < xs.size(); ++i) {
      const double cx = 0.5 * (xs[i] + xs[i + 1]), cy = 0.5 * (ys[j] + ys[j + 1]);
      const bool sidewalk = cx < blk.box.min().x() + swl || cx > blk.box.max().x() - swr ||
                            cy < blk.box.min().y() + swb || cy > blk.box.max().y() - swt;
      const uint32_t label = encode_label(sidewalk ? semantic::kSidewalk : semantic::kTerrain, 0);
      add_quad(w.ground, vertex(xs[i], ys[j]), vertex(xs[i + 1], ys[j]), vertex(xs[i + 1], ys[j + 1]),
               vertex(xs[i], ys[j + 1]), label, sidewalk ? 0.3f : 0.2f);
    }
  }
  // Kerb faces: the vertical step from the road up to the sidewalk.
  const uint32_t kerb_label = encode_label(semantic::kSidewalk, 0);
  for (const SideFrame& side : block_sides(w, blk)) {
    const int n = std::max(1, static_cast<int>(std::ceil(side.length_m / cell)));
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector2f a = side.at(side.length_m * k / n, 0);
      const Eigen::Vector2f c = side.at(side.length_m * (k + 1) / n, 0);
      const float za = float(w.road_height(a.x(), a.y())), zc = float(w.road_height(c.x(), c.y()));
      add_quad(w.ground, {a.x(), a.y(), za}, {c.x(), c.y(), zc}, {c.x(), c.y(), zc + kerb}, {a.x(), a.y(), za + kerb},
               kerb_label, 0.35f);
    }
  }
}

std::vector<Block> make_blocks(const World& w) {
  const auto& g = w.grid;
  const int nx = static_cast<int>(g.x.size()), ny = static_cast<int>(g.y.size());
  std::vector<Block> blocks;
  for (int j = -1; j < ny; ++j) {
    for (int i = -1; i < nx; ++i) {
      Block b;
      b.street[kLeft] = i >= 0;
      b.street[kRight] = i + 1 < nx;
      b.street[kBottom] = j >= 0;
      b.street[kTop] = j + 1 < ny;
      const double x0 = i >= 0 ? g.x[i] + 0.5 * g.x_width[i] : w.bounds.min().x();
      const double x1 = i + 1 < nx ? g.x[i + 1] - 0.5 * g.x_width[i + 1] : w.bounds.max().x();
      const double y0 = j >= 0 ? g.y[j] + 0.5 * g.y_width[j] : w.bounds.min().y();
      const double y1 = j + 1 < ny ? g.y[j + 1] - 0.5 * g.y_width[j + 1] : w.bounds.max().y();
      b.box = Eigen::AlignedBox2d(Eigen::Vector2d(x0, y0), Eigen::Vector2d(x1, y1));
      b.outer = i < 0 || j < 0 || i + 1 >= nx || j + 1 >= ny;
      b.line_ids = {i, i + 1, j, j + 1};
      blocks.push_back(b);
    }
  }
  return blocks;
}

std::vector<SideFrame> block_sides(const World& w, const Block& b) {
  // Sides run counter-clockwise around the block so `inward` is always the left normal.
  const Eigen::Vector2f lo = b.box.min().cast<float>(), hi = b.box.max().cast<float>();
  std::vector<SideFrame> sides;
  auto add = [&](Side s, Eigen::Vector2f origin, Eigen::Vector2f along, float length) {
    if (!b.street[s]) return;
    const uint64_t key = (s == kLeft || s == kRight ? 1000u : 2000u) + b.line_ids[s];
    sides.push_back({origin, along, Eigen::Vector2f(-along.y(), along.x()), length, key});
  };
  add(kBottom, {lo.x(), lo.y()}, {1, 0}, hi.x() - lo.x());
  add(kRight, {hi.x(), lo.y()}, {0, 1}, hi.y() - lo.y());
  add(kTop, {hi.x(), hi.y()}, {-1, 0}, hi.x() - lo.x());
  add(kLeft, {lo.x(), hi.y()}, {0, -1}, hi.y() - lo.y());
  return sides;
}

}  // namespace detail

World generate_world(const WorldConfig& config) {
  config.validate();
  Rng rng(mix_seed(config.seed, 0x5eed));
  World w;
  w.config = config;
  detail::layout_lines(config, rng, config.blocks_x, w.grid.x, w.grid.x_width, w.grid.x_lanes);
  detail::layout_lines(config, rng, config.blocks_y, w.grid.y, w.grid.y_width, w.grid.y_lanes);
  const double margin = 0.5 * (config.block_min_m + config.block_max_m) * 0.5;
  w.bounds = Eigen::AlignedBox2d(Eigen::Vector2d(w.grid.x.front() - margin, w.grid.y.front() - margin),
                                 Eigen::Vector2d(w.grid.x.back() + margin, w.grid.y.back() + margin));
  // Terrain: each term uses at most a third of the grade budget, so |grad h| <= max_grade.
  const double g = config.max_grade / 3.0;
  auto& t = w.terrain;
  t.grade_x = rng.uniform(-g, g) / std::sqrt(2.0);
  t.grade_y = rng.uniform(-g, g) / std::sqrt(2.0);
  t.wavelength1 = rng.uniform(250, 500);
  t.wavelength2 = rng.uniform(250, 500);
  t.amp1 = rng.uniform(0.3, 1.0) * g * t.wavelength1 / 6.283185307179586;
  t.amp2 = rng.uniform(0.3, 1.0) * g * t.wavelength2 / 6.283185307179586;
  t.phase1 = rng.uniform(0, 6.283185307179586);
  t.phase2 = rng.uniform(0, 6.283185307179586);
  detail::build_graph(w);
  detail::build_road_mesh(w);
  for (const auto& block : detail::make_blocks(w)) {
    detail::build_block_ground(w, block);
    detail::populate_block(w, block, rng);
  }
  detail::park_cars(w, rng);
  return w;
}

}  // namespace segmatch::sim
