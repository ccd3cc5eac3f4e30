// The world some time later: parked cars left, moved or arrived, pedestrians on the
// sidewalks, vegetation trimmed, regrown or planted. This is what makes the second
// traversal a realistic revisit rather than a replay.
#include "world_internal.h"

#include <algorithm>
#include <cmath>

namespace segmatch::sim {
namespace {

using Eigen::Vector2f;

void relabel(WorldObject& o, uint16_t instance) {
  o.instance = instance;
  for (auto& p : o.parts) p.label = encode_label(label_class(p.label), instance);
}

void translate(WorldObject& o, const Eigen::Vector3f& delta) {
  o.position += delta.head<2>();
  for (auto& p : o.parts) {
    p.a += delta;
    if (p.shape == Shape::kTriangle) {
      p.b += delta;
      p.c += delta;
    }
  }
}

bool overlaps_car(const World& w, const WorldObject& car, size_t self) {
  for (size_t k = 0; k < w.objects.size(); ++k) {
    const auto& o = w.objects[k];
    if (k == self || o.kind != ObjectKind::kCar) continue;
    if ((o.position - car.position).norm() < o.half_extents.x() + car.half_extents.x() + 0.3f) return true;
  }
  return false;
}

void change_cars(World& w, Rng& rng, const ChangeConfig& c) {
  std::vector<WorldObject> kept;
  kept.reserve(w.objects.size());
  for (auto& o : w.objects) {
    if (o.kind != ObjectKind::kCar) {
      kept.push_back(std::move(o));
      continue;
    }
    const double r = rng.uniform();
    if (r < c.car_removed_fraction) continue;
    if (r < c.car_removed_fraction + c.car_moved_fraction) {
      // Re-parked a few metres along the kerb: a different object for matching purposes.
      const Vector2f fwd(std::cos(o.yaw), std::sin(o.yaw));
      const float shift = static_cast<float>(rng.uniform(1.5, 6.0)) * (rng.bernoulli(0.5) ? 1.f : -1.f);
      const Vector2f p = o.position + shift * fwd;
      const float dz =
          static_cast<float>(w.surface_height(p.x(), p.y()) - w.surface_height(o.position.x(), o.position.y()));
      translate(o, Eigen::Vector3f(shift * fwd.x(), shift * fwd.y(), dz));
      relabel(o, w.allocate_instance());
    }
    kept.push_back(std::move(o));
  }
  w.objects = std::move(kept);
  // Moved cars that now overlap another car are taken away (they could not park there).
  for (size_t k = w.objects.size(); k-- > 0;) {
    if (w.objects[k].kind == ObjectKind::kCar && overlaps_car(w, w.objects[k], k))
      w.objects.erase(w.objects.begin() + static_cast<long>(k));
  }
  detail::fill_parking(w, rng, c.new_car_fill);
}

void add_pedestrians(World& w, Rng& rng, const ChangeConfig& c) {
  const auto& g = w.streets;
  const float sw = w.config.sidewalk_width_m;
  for (const auto& edge : g.edges) {
    const Vector2f A = g.nodes[edge.a].cast<float>(), B = g.nodes[edge.b].cast<float>();
    const float len = (B - A).norm();
    const Vector2f d = (B - A) / len, right(d.y(), -d.x());
    const int n = static_cast<int>(std::floor(c.pedestrians_per_100m * len / 100.0f + rng.uniform()));
    for (int k = 0; k < n; ++k) {
      const float s = static_cast<float>(rng.uniform(12.0, std::max(12.5f, len - 12.0f)));
      const float side = rng.bernoulli(0.5) ? 1.0f : -1.0f;
      const float lateral = 0.5f * edge.width_m + static_cast<float>(rng.uniform(0.6, sw - 0.6));
      detail::PartBuilder b{w, rng, w.allocate_instance()};
      w.objects.push_back(detail::make_pedestrian(b, A + s * d + side * lateral * right));
    }
  }
}

void change_vegetation(World& w, Rng& rng, const ChangeConfig& c) {
  std::vector<Vector2f> removed_bushes;
  std::vector<WorldObject> kept;
  kept.reserve(w.objects.size());
  for (auto& o : w.objects) {
    if (o.kind == ObjectKind::kTree && rng.bernoulli(c.vegetation_changed_fraction)) {
      detail::regrow_crown(o, rng);  // same tree (same instance), new crown
    } else if (o.kind == ObjectKind::kBush && rng.bernoulli(c.vegetation_changed_fraction)) {
      removed_bushes.push_back(o.position);
      continue;
    }
    kept.push_back(std::move(o));
  }
  w.objects = std::move(kept);
  // As many new bushes as were removed, planted a few metres from the old ones.
  for (const Vector2f& p : removed_bushes) {
    const double a = rng.uniform(0, 6.283185307179586), r = rng.uniform(2.0, 4.0);
    const Vector2f q = p + static_cast<float>(r) * Vector2f(std::cos(a), std::sin(a));
    if (w.on_road(q.x(), q.y())) continue;
    detail::PartBuilder b{w, rng, w.allocate_instance()};
    w.objects.push_back(detail::make_bush(b, q));
  }
}

}  // namespace

World change_world(const World& world, const ChangeConfig& config) {
  World w = world;
  Rng rng(mix_seed(world.config.seed, config.seed, 0xc4a9));
  change_cars(w, rng, config);
  add_pedestrians(w, rng, config);
  change_vegetation(w, rng, config);
  return w;
}

}  // namespace segmatch::sim
