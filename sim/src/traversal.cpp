#include "segmatch/sim/traversal.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <stdexcept>

namespace segmatch::sim {
namespace {

using Eigen::Vector2d;
constexpr double kStepM = 0.1;  // path sampling step

int edge_between(const StreetGraph& g, int a, int b) {
  for (int e : g.node_edges[a])
    if (g.other_end(e, a) == b) return e;
  throw std::logic_error("route nodes are not adjacent");
}

// Directed edge key: the same street driven a->b or b->a are different keys.
int directed(const StreetGraph& g, int from, int to) {
  const int e = edge_between(g, from, to);
  return 2 * e + (g.edges[e].a == from ? 0 : 1);
}

double route_length(const StreetGraph& g, const Route& r) {
  double len = 0;
  for (size_t i = 0; i + 1 < r.nodes.size(); ++i) len += (g.nodes[r.nodes[i + 1]] - g.nodes[r.nodes[i]]).norm();
  return len;
}

// Random walk that never turns back; weight(cur, next) scores each continuation and
// `used` counts how often each edge was driven so far (updated here).
template <typename WeightFn>
Route walk(const StreetGraph& g, int start, int prev, double length_m, Rng& rng, std::map<int, int>& used,
           WeightFn&& weight) {
  Route r;
  r.nodes.push_back(start);
  double len = 0;
  while (len < length_m) {
    const int cur = r.nodes.back();
    std::vector<std::pair<int, double>> options;
    double total = 0;
    for (int e : g.node_edges[cur]) {
      const int next = g.other_end(e, cur);
      if (next == prev) continue;
      const double w = weight(cur, next);
      options.emplace_back(next, w);
      total += w;
    }
    if (options.empty()) break;
    double pick = rng.uniform() * total;
    int next = options.back().first;
    for (const auto& [n, w] : options) {
      if ((pick -= w) <= 0) {
        next = n;
        break;
      }
    }
    len += (g.nodes[next] - g.nodes[cur]).norm();
    ++used[edge_between(g, cur, next)];
    prev = cur;
    r.nodes.push_back(next);
  }
  return r;
}

struct PathSample {
  Vector2d p;
  double heading;
  double curvature;
  int leg;  // index of the route edge being driven
};

void add_straight(std::vector<PathSample>& out, const Vector2d& a, const Vector2d& b, int leg) {
  const double len = (b - a).norm();
  if (len < 1e-9) return;
  const double heading = std::atan2(b.y() - a.y(), b.x() - a.x());
  const int n = std::max(1, static_cast<int>(std::ceil(len / kStepM)));
  for (int i = 0; i < n; ++i) out.push_back({a + (b - a) * (double(i) / n), heading, 0.0, leg});
}

// Circular arc tangent to direction d_in at `start`, turning by `angle` (left positive).
Vector2d add_arc(std::vector<PathSample>& out, const Vector2d& start, const Vector2d& d_in, double radius, double angle,
                 int leg) {
  const double side = angle > 0 ? 1.0 : -1.0;
  const Vector2d normal = side * Vector2d(-d_in.y(), d_in.x());
  const Vector2d centre = start + radius * normal;
  const double h0 = std::atan2(d_in.y(), d_in.x());
  const int n = std::max(2, static_cast<int>(std::ceil(std::abs(angle) * radius / kStepM)));
  Vector2d p = start;
  for (int i = 0; i < n; ++i) {
    const double a = angle * i / n;
    const Vector2d rel = start - centre;
    p = centre + Eigen::Rotation2Dd(a) * rel;
    out.push_back({p, h0 + a, 1.0 / radius, i < n / 2 ? leg : leg + 1});
  }
  return centre + Eigen::Rotation2Dd(angle) * (start - centre);
}

std::vector<PathSample> lane_path(const World& world, const Route& route, const DriveConfig& c) {
  const auto& g = world.streets;
  const size_t legs = route.nodes.size() - 1;
  std::vector<Vector2d> dir(legs), base(legs);
  for (size_t i = 0; i < legs; ++i) {
    const Vector2d a = g.nodes[route.nodes[i]], b = g.nodes[route.nodes[i + 1]];
    const auto& edge = g.edges[edge_between(g, route.nodes[i], route.nodes[i + 1])];
    dir[i] = (b - a).normalized();
    const int lane = (edge.lanes_per_direction == 2 && c.inner_lane) ? 0 : edge.lanes_per_direction - 1;
    const double offset = (lane + 0.5) * world.config.lane_width_m - c.lane_shift_m;
    base[i] = a + offset * Vector2d(dir[i].y(), -dir[i].x());  // right of travel
  }
  std::vector<PathSample> out;
  const double first_len = (g.nodes[route.nodes[1]] - g.nodes[route.nodes[0]]).norm();
  Vector2d cursor = base[0] + dir[0] * std::min(20.0, first_len / 3);
  for (size_t i = 1; i < legs; ++i) {
    const double cross = dir[i - 1].x() * dir[i].y() - dir[i - 1].y() * dir[i].x();
    const double angle = std::atan2(cross, dir[i - 1].dot(dir[i]));
    if (std::abs(angle) < 1e-6) continue;  // straight on through the intersection
    // Corner point: intersection of the two lane lines.
    const Vector2d rhs = base[i] - base[i - 1];
    const double t = (rhs.x() * dir[i].y() - rhs.y() * dir[i].x()) / cross;
    const Vector2d corner = base[i - 1] + t * dir[i - 1];
    const double radius = angle > 0 ? c.left_turn_radius_m : c.right_turn_radius_m;
    const double tangent = radius * std::tan(std::abs(angle) / 2);
    add_straight(out, cursor, corner - tangent * dir[i - 1], static_cast<int>(i - 1));
    cursor = add_arc(out, corner - tangent * dir[i - 1], dir[i - 1], radius, angle, static_cast<int>(i - 1));
  }
  const Vector2d end =
      g.nodes[route.nodes.back()] + (base.back() - g.nodes[route.nodes[legs - 1]]) -
      dir.back() * std::min(20.0, (g.nodes[route.nodes.back()] - g.nodes[route.nodes[legs - 1]]).norm() / 3);
  add_straight(out, cursor, end, static_cast<int>(legs - 1));
  out.push_back({end, out.back().heading, 0.0, static_cast<int>(legs - 1)});
  return out;
}

// Speed limited by lateral acceleration in turns and by acceleration/braking along the path.
std::vector<double> speed_profile(const std::vector<PathSample>& path, const DriveConfig& c) {
  std::vector<double> v(path.size());
  for (size_t i = 0; i < path.size(); ++i)
    v[i] = path[i].curvature > 0 ? std::min(c.cruise_speed_mps, std::sqrt(c.max_lateral_accel_mps2 / path[i].curvature))
                                 : c.cruise_speed_mps;
  for (size_t i = 1; i < v.size(); ++i)
    v[i] = std::min(v[i], std::sqrt(v[i - 1] * v[i - 1] + 2 * c.max_accel_mps2 * kStepM));
  for (size_t i = v.size() - 1; i-- > 0;)
    v[i] = std::min(v[i], std::sqrt(v[i + 1] * v[i + 1] + 2 * c.max_accel_mps2 * kStepM));
  return v;
}

// Vehicle attitude on the terrain: z along the road normal, x along the heading.
Pose3d pose_on_road(const World& w, const Vector2d& p, double heading, double height) {
  constexpr double h = 0.5;
  const double dzdx = (w.road_height(p.x() + h, p.y()) - w.road_height(p.x() - h, p.y())) / (2 * h);
  const double dzdy = (w.road_height(p.x(), p.y() + h) - w.road_height(p.x(), p.y() - h)) / (2 * h);
  const Eigen::Vector3d z = Eigen::Vector3d(-dzdx, -dzdy, 1.0).normalized();
  Eigen::Vector3d x(std::cos(heading), std::sin(heading), 0.0);
  x = (x - x.dot(z) * z).normalized();
  Pose3d T = Pose3d::Identity();
  T.linear().col(0) = x;
  T.linear().col(1) = z.cross(x);
  T.linear().col(2) = z;
  T.translation() = Eigen::Vector3d(p.x(), p.y(), w.road_height(p.x(), p.y())) + height * z;
  return T;
}

}  // namespace

Route plan_route(const StreetGraph& g, double length_m, Rng& rng) {
  std::map<int, int> used;
  const int start = static_cast<int>(rng.index(g.nodes.size()));
  return walk(g, start, -1, length_m, rng, used, [&](int cur, int next) {
    const auto it = used.find(edge_between(g, cur, next));
    return 1.0 / (1.0 + 6.0 * (it == used.end() ? 0 : it->second));
  });
}

Route plan_loop_route(const StreetGraph& g, int again) {
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const auto& n : g.nodes) centre += n;
  centre /= static_cast<double>(g.nodes.size());
  std::vector<int> outer;
  for (size_t i = 0; i < g.nodes.size(); ++i)
    if (g.node_edges[i].size() < 4) outer.push_back(static_cast<int>(i));
  auto angle = [&](int i) { return std::atan2(g.nodes[i].y() - centre.y(), g.nodes[i].x() - centre.x()); };
  std::sort(outer.begin(), outer.end(), [&](int a, int b) { return angle(a) > angle(b); });  // clockwise
  Route r;
  r.nodes = outer;
  for (int k = 0; k <= again; ++k) r.nodes.push_back(outer[static_cast<size_t>(k) % outer.size()]);
  for (size_t i = 0; i + 1 < r.nodes.size(); ++i) {
    const auto& edges = g.node_edges[r.nodes[i]];
    if (std::none_of(edges.begin(), edges.end(), [&](int e) { return g.other_end(e, r.nodes[i]) == r.nodes[i + 1]; }))
      throw std::runtime_error("the city's outer nodes do not form a closed route");
  }
  return r;
}

Route plan_revisit_route(const StreetGraph& g, const Route& first, double length_m, Rng& rng) {
  std::set<int> first_dir;
  for (size_t i = 0; i + 1 < first.nodes.size(); ++i) first_dir.insert(directed(g, first.nodes[i], first.nodes[i + 1]));
  Route best;
  double best_score = -1;
  for (int attempt = 0; attempt < 40; ++attempt) {
    const size_t k = 1 + rng.index(first.nodes.size() - 1);
    std::map<int, int> used;
    Route r = walk(g, first.nodes[k], first.nodes[k - 1], length_m, rng, used, [&](int cur, int next) {
      const int key = directed(g, cur, next), rev = key ^ 1;
      double w = 1.0 + 3.0 * first_dir.count(key) + 3.0 * first_dir.count(rev);
      if (used.count(key >> 1)) w *= 0.15;
      return w;
    });
    // Score: credit for each of same-direction, opposite-direction and new streets up to a
    // share of the route, so routes that mix all three win, and partial mixes beat none.
    double same = 0, opposite = 0, fresh = 0;
    for (size_t i = 0; i + 1 < r.nodes.size(); ++i) {
      const int key = directed(g, r.nodes[i], r.nodes[i + 1]);
      const double len = (g.nodes[r.nodes[i + 1]] - g.nodes[r.nodes[i]]).norm();
      (first_dir.count(key) ? same : first_dir.count(key ^ 1) ? opposite : fresh) += len;
    }
    const double total = route_length(g, r);
    const double score = std::min(same, 0.35 * total) + std::min(opposite, 0.35 * total) + std::min(fresh, 0.2 * total);
    if (score > best_score) {
      best_score = score;
      best = r;
    }
  }
  return best;
}

Traversal drive(const World& world, const Route& route, const DriveConfig& c) {
  if (route.nodes.size() < 2) throw std::invalid_argument("route needs at least two nodes");
  const auto path = lane_path(world, route, c);
  const auto v = speed_profile(path, c);
  std::vector<double> t(path.size(), 0.0), s(path.size(), 0.0);
  for (size_t i = 1; i < path.size(); ++i) {
    const double ds = (path[i].p - path[i - 1].p).norm();
    s[i] = s[i - 1] + ds;
    t[i] = t[i - 1] + ds / std::max(0.5, 0.5 * (v[i] + v[i - 1]));
  }
  Traversal out;
  size_t i = 0;
  for (double time = 0.0; time <= t.back(); time += c.scan_period_s) {
    while (i + 2 < t.size() && t[i + 1] < time) ++i;
    const double f = std::clamp((time - t[i]) / std::max(1e-9, t[i + 1] - t[i]), 0.0, 1.0);
    const Vector2d p = path[i].p + f * (path[i + 1].p - path[i].p);
    const double dh = std::remainder(path[i + 1].heading - path[i].heading, 2 * M_PI);
    const int leg = path[i].leg;
    out.times_s.push_back(out.times_s.size() * c.scan_period_s);
    out.T_world_lidar.push_back(pose_on_road(world, p, path[i].heading + f * dh, c.sensor_height_m));
    out.odometer_m.push_back(s[i] + f * (s[i + 1] - s[i]));
    out.edge.push_back(edge_between(world.streets, route.nodes[leg], route.nodes[leg + 1]));
    out.forward.push_back(world.streets.edges[out.edge.back()].a == route.nodes[leg]);
  }
  return out;
}

std::vector<RevisitMatch> match_revisits(const Traversal& reference, const Traversal& revisit) {
  std::vector<RevisitMatch> out;
  for (size_t i = 0; i < revisit.size(); ++i) {
    const Eigen::Vector3d p = revisit.T_world_lidar[i].translation();
    RevisitMatch m;
    m.frame = static_cast<int>(i);
    m.distance_m = 1e300;
    for (size_t j = 0; j < reference.size(); ++j) {
      const double d = (reference.T_world_lidar[j].translation() - p).head<2>().norm();
      if (d < m.distance_m) {
        m.distance_m = d;
        m.reference_frame = static_cast<int>(j);
      }
    }
    if (m.reference_frame >= 0) {
      const Eigen::Vector3d a = revisit.T_world_lidar[i].linear().col(0);
      const Eigen::Vector3d b = reference.T_world_lidar[m.reference_frame].linear().col(0);
      m.heading_diff_deg =
          std::acos(std::clamp(a.head<2>().normalized().dot(b.head<2>().normalized()), -1.0, 1.0)) * 180.0 / M_PI;
    }
    out.push_back(m);
  }
  return out;
}

}  // namespace segmatch::sim
