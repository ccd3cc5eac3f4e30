// Where objects go: buildings on lots along the streets, furniture and trees on sidewalks,
// parks with trees and bushes, and cars in the parking lanes.
#include "world_internal.h"

#include <algorithm>
#include <cmath>

namespace segmatch::sim::detail {
namespace {

using Eigen::Vector2f;

// Occupied intervals along one sidewalk, so furniture does not overlap.
class Line1D {
 public:
  bool free(float s, float radius) const {
    for (const auto& [a, b] : used_)
      if (s + radius > a && s - radius < b) return false;
    return true;
  }
  void take(float s, float radius) { used_.emplace_back(s - radius, s + radius); }

 private:
  std::vector<std::pair<float, float>> used_;
};

PartBuilder builder(World& w, Rng& rng) { return PartBuilder{w, rng, w.allocate_instance()}; }

// Sidewalk widths at the start (s = 0) and end (s = length) of a side: those of the
// perpendicular streets the side runs into.
std::pair<float, float> end_sidewalks(const World& w, const Block& b, const SideFrame& side) {
  const float sw = w.config.sidewalk_width_m;
  auto width = [&](Side s) { return b.street[s] ? sw : 0.0f; };
  if (side.along.x() > 0.5f) return {width(kLeft), width(kRight)};
  if (side.along.x() < -0.5f) return {width(kRight), width(kLeft)};
  if (side.along.y() > 0.5f) return {width(kBottom), width(kTop)};
  return {width(kTop), width(kBottom)};
}

void add_boundary(World& w, Rng& rng, const SideFrame& side, float s0, float s1, float o) {
  if (s1 - s0 < 1.5f) return;
  PartBuilder b = builder(w, rng);
  const double r = rng.uniform();
  w.objects.push_back(r < 0.45   ? make_hedge(b, side, s0, s1, o)
                      : r < 0.75 ? make_wall(b, side, s0, s1, o)
                                 : make_fence(b, side, s0, s1, o));
}

// Furniture and street trees on the sidewalk of one side. The street's style (lamp design
// and spacing, tree rows) comes from the street line, so repeated objects exist as in a city.
void furnish_sidewalk(World& w, const Block& blk, const SideFrame& side, Rng& rng) {
  const float sw = w.config.sidewalk_width_m;
  Rng style(mix_seed(w.config.seed, side.street_key, 0x57e1));
  const float lamp_spacing = static_cast<float>(style.uniform(24, 36));
  const float lamp_height = static_cast<float>(style.uniform(6.5, 9.5));
  const bool lamps_both_sides = style.bernoulli(0.6);
  const bool tree_lined = style.bernoulli(w.config.tree_street_fraction);
  const float tree_spacing = static_cast<float>(style.uniform(7, 12));
  const float tree_scale = static_cast<float>(style.uniform(0.8, 1.3));
  const auto [sw0, sw1] = end_sidewalks(w, blk, side);
  const float s0 = sw0 + 2.0f, s1 = side.length_m - sw1 - 2.0f;
  if (s1 - s0 < 4.0f) return;
  const float to_road = std::atan2(-side.inward.y(), -side.inward.x());
  Line1D line;
  // Lamps on one side only go on the side whose inward normal points to +x or +y.
  if (lamps_both_sides || side.inward.x() + side.inward.y() > 0) {
    for (float s = s0 + static_cast<float>(rng.uniform(0, lamp_spacing)); s < s1; s += lamp_spacing) {
      const float sj = s + static_cast<float>(rng.uniform(-0.3, 0.3));
      PartBuilder b = builder(w, rng);
      w.objects.push_back(make_street_lamp(b, side.at(sj, 0.5f), to_road, lamp_height));
      line.take(sj, 1.0f);
    }
  }
  if (tree_lined) {
    const float o = sw >= 2.5f ? 1.5f : sw + 1.5f;
    for (float s = s0 + 2.0f; s < s1 - 1.0f; s += tree_spacing * static_cast<float>(rng.uniform(0.93, 1.07))) {
      if (!line.free(s, 1.5f)) continue;
      PartBuilder b = builder(w, rng);
      w.objects.push_back(make_tree(b, side.at(s, o), tree_scale * static_cast<float>(rng.uniform(0.85, 1.15))));
      line.take(s, 1.5f);
    }
  }
  // Signs (often near the corner), utility poles and benches at random.
  auto scatter = [&](float per_100m, float radius, auto&& make) {
    const int n = static_cast<int>(std::floor(per_100m * (s1 - s0) / 100.0f + rng.uniform()));
    for (int k = 0; k < n; ++k) {
      const float s = static_cast<float>(rng.uniform(s0, s1));
      if (!line.free(s, radius)) continue;
      PartBuilder b = builder(w, rng);
      w.objects.push_back(make(b, s));
      line.take(s, radius);
    }
  };
  if (rng.bernoulli(0.5) && line.free(s0 + 0.5f, 0.8f)) {
    PartBuilder b = builder(w, rng);
    w.objects.push_back(make_sign(b, side.at(s0 + 0.5f, 0.4f), to_road));
    line.take(s0 + 0.5f, 0.8f);
  }
  scatter(1.5f, 0.8f, [&](PartBuilder& b, float s) { return make_sign(b, side.at(s, 0.4f), to_road); });
  scatter(1.2f, 0.8f, [&](PartBuilder& b, float s) { return make_pole(b, side.at(s, 0.45f)); });
  scatter(1.0f, 1.2f, [&](PartBuilder& b, float s) { return make_bench(b, side.at(s, sw - 0.5f), side.yaw()); });
}

void build_lots(World& w, const SideFrame& side, float a, float b_end, float depth_max, Rng& rng,
                const std::pair<float, float>& heights) {
  const float sw = w.config.sidewalk_width_m;
  const float setback_base = rng.bernoulli(0.5) ? 0.0f : static_cast<float>(rng.uniform(0.5, 4.0));
  float s = a;
  while (b_end - s > 8.0f) {
    float width = static_cast<float>(rng.uniform(9, 28));
    if (b_end - s - width < 8.0f) width = b_end - s;
    if (rng.bernoulli(0.85) && depth_max >= 8.0f) {
      const float setback = std::max(0.0f, setback_base + static_cast<float>(rng.uniform(-0.4, 0.4)));
      const float depth = static_cast<float>(rng.uniform(std::min(10.0f, depth_max), depth_max)) - setback;
      const float height = static_cast<float>(rng.uniform(heights.first, heights.second));
      PartBuilder bb = builder(w, rng);
      w.objects.push_back(make_building(bb, side, s, sw + setback, width, std::max(6.0f, depth), height));
      if (setback > 1.8f && rng.bernoulli(0.35)) add_boundary(w, rng, side, s + 0.5f, s + width - 0.5f, sw + 0.3f);
    } else {
      // An open lot: a boundary along the sidewalk and some vegetation behind it.
      if (rng.bernoulli(0.7)) add_boundary(w, rng, side, s + 0.3f, s + width - 0.3f, sw + 0.3f);
      const int plants = rng.uniform_int(0, 3);
      for (int k = 0; k < plants; ++k) {
        PartBuilder pb = builder(w, rng);
        const Vector2f p = side.at(static_cast<float>(rng.uniform(s + 1.5, s + width - 1.5)),
                                   sw + static_cast<float>(rng.uniform(2.5, std::max(3.0f, depth_max - 1.0f))));
        w.objects.push_back(rng.bernoulli(0.5) ? make_tree(pb, p, static_cast<float>(rng.uniform(0.8, 1.3)))
                                               : make_bush(pb, p));
      }
    }
    s += width + (rng.bernoulli(0.3) ? static_cast<float>(rng.uniform(1.0, 4.0)) : 0.0f);
  }
}

void build_block_buildings(World& w, const Block& blk, Rng& rng) {
  const float sw = w.config.sidewalk_width_m;
  const auto sides = block_sides(w, blk);
  const float inner_w = float(blk.box.sizes().x()) - (blk.street[kLeft] + blk.street[kRight]) * sw;
  const float inner_h = float(blk.box.sizes().y()) - (blk.street[kBottom] + blk.street[kTop]) * sw;
  // Block style: low, mid or high rise.
  static const std::pair<float, float> kHeights[3] = {{5.0f, 12.0f}, {10.0f, 22.0f}, {18.0f, 40.0f}};
  const auto heights = kHeights[rng.index(3)];
  const float depth_x = std::min(22.0f, 0.5f * inner_h - 1.5f);  // lots on bottom/top sides
  const float depth_y = std::min(22.0f, 0.5f * inner_w - 1.5f);  // lots on left/right sides
  for (const SideFrame& side : sides) {
    const bool horizontal = std::abs(side.along.x()) > 0.5f;
    const auto [sw0, sw1] = end_sidewalks(w, blk, side);
    float a = sw0 + 0.5f, b = side.length_m - sw1 - 0.5f;
    if (!horizontal) {
      // Leave the corners to the lots of the horizontal sides.
      const bool lo_taken = blk.street[kBottom], hi_taken = blk.street[kTop];
      const bool start_is_bottom = side.along.y() > 0;
      if (start_is_bottom ? lo_taken : hi_taken) a += depth_x + 1.0f;
      if (start_is_bottom ? hi_taken : lo_taken) b -= depth_x + 1.0f;
    }
    build_lots(w, side, a, b, horizontal ? depth_x : depth_y, rng, heights);
  }
}

void build_park(World& w, const Block& blk, Rng& rng) {
  const float sw = w.config.sidewalk_width_m;
  const Eigen::Vector2f lo = blk.box.min().cast<float>() + Vector2f(sw + 1, sw + 1);
  const Eigen::Vector2f hi = blk.box.max().cast<float>() - Vector2f(sw + 1, sw + 1);
  if ((hi - lo).minCoeff() < 5.0f) return;
  const float area = (hi - lo).prod();
  std::vector<Vector2f> placed;
  auto place = [&](int count, float min_dist, bool tree) {
    for (int k = 0, tries = 0; k < count && tries < 30 * count; ++tries) {
      const Vector2f p(static_cast<float>(rng.uniform(lo.x(), hi.x())),
                       static_cast<float>(rng.uniform(lo.y(), hi.y())));
      bool ok = true;
      for (const auto& q : placed) ok &= (p - q).norm() >= min_dist;
      if (!ok) continue;
      placed.push_back(p);
      PartBuilder b = builder(w, rng);
      w.objects.push_back(tree ? make_tree(b, p, static_cast<float>(rng.uniform(0.8, 1.5))) : make_bush(b, p));
      ++k;
    }
  };
  place(static_cast<int>(area / 220.0f), 5.5f, true);
  place(static_cast<int>(area / 300.0f), 2.5f, false);
  for (const SideFrame& side : block_sides(w, blk)) {
    const auto [sw0, sw1] = end_sidewalks(w, blk, side);
    if (rng.bernoulli(0.6)) add_boundary(w, rng, side, sw0 + 1.0f, side.length_m - sw1 - 1.0f, sw + 0.4f);
  }
}

}  // namespace

void populate_block(World& w, const Block& blk, Rng& rng) {
  const bool park = !blk.outer && rng.bernoulli(w.config.park_block_fraction);
  if (park) {
    build_park(w, blk, rng);
  } else {
    build_block_buildings(w, blk, rng);
  }
  for (const SideFrame& side : block_sides(w, blk)) furnish_sidewalk(w, blk, side, rng);
}

void fill_parking(World& w, Rng& rng, float fill) {
  const auto& g = w.streets;
  const float park_w = w.config.parking_lane_width_m;
  for (size_t e = 0; e < g.edges.size(); ++e) {
    const auto& edge = g.edges[e];
    const Eigen::Vector2f A = g.nodes[edge.a].cast<float>(), B = g.nodes[edge.b].cast<float>();
    const float len = (B - A).norm();
    const Vector2f d = (B - A) / len, right(d.y(), -d.x());
    auto clearance = [&](int node) {
      float widest = 0;
      for (int k : g.node_edges[node]) widest = std::max(widest, g.edges[k].width_m);
      return 0.5f * widest + 6.0f;
    };
    const float start = clearance(edge.a), end = len - clearance(edge.b);
    for (int k : {1, -1}) {  // +1: right of A->B, traffic runs A->B there
      const float lateral = 0.5f * edge.width_m - 0.5f * park_w;
      const Vector2f lane = A + k * lateral * right;
      Line1D line;
      for (const auto& o : w.objects) {
        if (o.kind != ObjectKind::kCar) continue;
        const Vector2f rel = o.position - lane;
        if (std::abs(rel.dot(right)) < 1.2f) line.take(rel.dot(d), o.half_extents.x() + 0.5f);
      }
      const float yaw = std::atan2(k * d.y(), k * d.x());
      for (float s = start; s < end - 3.7f;) {
        if (!rng.bernoulli(fill)) {
          s += static_cast<float>(rng.uniform(2.0, 8.0));
          continue;
        }
        const int model = static_cast<int>(rng.index(kCarModels));
        const float L = car_length(model);
        if (s + L > end) break;
        if (line.free(s + 0.5f * L, 0.5f * L + 0.3f)) {
          PartBuilder b = builder(w, rng);
          const Vector2f p = lane + (s + 0.5f * L) * d + static_cast<float>(rng.normal(0, 0.1)) * right;
          w.objects.push_back(make_car(b, p, yaw + static_cast<float>(rng.normal(0, 0.03)), model));
          line.take(s + 0.5f * L, 0.5f * L);
        }
        s += L + static_cast<float>(rng.uniform(0.6, 1.6));
      }
    }
  }
}

void park_cars(World& w, Rng& rng) { fill_parking(w, rng, w.config.parked_car_fill); }

}  // namespace segmatch::sim::detail
