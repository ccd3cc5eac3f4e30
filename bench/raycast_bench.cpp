// segmatch-bench-raycast: micro-benchmark of the LiDAR ray caster.
//
// Builds a synthetic, city-like stress scene (ground mesh of 5 m triangles over 400 x 400 m,
// ~3000 buildings with facade detail boxes, poles and tree trunks as cylinders, tree crowns
// as ellipsoids, cars as boxes), reports the BVH build time, then simulates HDL-64E scans
// from poses along a street, one thread, and prints the median scans/s and rays/s.
//
// Usage: segmatch-bench-raycast [--scans N] [--details N] [--seed N]
//   --details  facade detail boxes per street-facing building (default 36: ~100k
//              primitives in total; 90 gives ~200k, 150 ~300k)
#include "segmatch/core/common/types.h"
#include "segmatch/core/detail/random.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/raycaster.h"
#include "segmatch/sim/scene.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <time.h>  // clock_gettime(CLOCK_THREAD_CPUTIME_ID)

namespace {

using segmatch::encode_label;
using segmatch::Rng;
using segmatch::sim::Primitive;
using segmatch::sim::Scene;
using Clock = std::chrono::steady_clock;

constexpr uint16_t kRoad = 40, kSidewalk = 48, kBuilding = 50, kCar = 10, kVegetation = 70, kTrunk = 71, kPole = 80;
constexpr float kHalfSize = 200.0f;   // world spans [-200, 200]^2
constexpr float kBlockPitch = 40.0f;  // street centre lines every 40 m
constexpr float kRoadHalfWidth = 6.0f;
constexpr float kPi = 3.14159265f;

float ground_height(float x, float y) { return 0.4f * std::sin(x / 37.0f) * std::cos(y / 53.0f) + 0.002f * x; }

// Distance from the nearest street centre line (x or y direction).
bool on_road(float x, float y) {
  auto dist = [](float v) {
    const float m = std::fmod(v + kHalfSize, kBlockPitch);
    return std::min(m, kBlockPitch - m);
  };
  return dist(x) < kRoadHalfWidth || dist(y) < kRoadHalfWidth;
}

// Ground: 80 x 80 cells of 5 m, two triangles each.
void add_ground(Scene* scene) {
  const float cell = 5.0f;
  const int n = static_cast<int>(2.0f * kHalfSize / cell);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const float x0 = -kHalfSize + i * cell, y0 = -kHalfSize + j * cell;
      const float x1 = x0 + cell, y1 = y0 + cell;
      const Eigen::Vector3f p00(x0, y0, ground_height(x0, y0)), p10(x1, y0, ground_height(x1, y0)),
          p01(x0, y1, ground_height(x0, y1)), p11(x1, y1, ground_height(x1, y1));
      const uint16_t cls = on_road(x0 + 2.5f, y0 + 2.5f) ? kRoad : kSidewalk;
      scene->push_back(Primitive::triangle(p00, p10, p11, encode_label(cls, 0), 0.25f));
      scene->push_back(Primitive::triangle(p00, p11, p01, encode_label(cls, 0), 0.25f));
    }
  }
}

// The street-facing buildings of one block (4 per side), each with a roof structure and facade
// details (sills, balconies, pillars) on the street side.
void add_block_buildings(Rng& rng, float bx0, float by0, float side, int details_per_building, Scene* scene,
                         uint16_t* instance, int* buildings) {
  for (int s = 0; s < 4; ++s) {
    for (int k = 0; k < 4; ++k) {
      // Position along the side, facade facing outwards.
      const float along = (k + 0.5f) * side / 4.0f;
      const float depth = static_cast<float>(rng.uniform(4.0, 6.0));
      const float front = side / 8.0f - 0.15f;
      const float height = static_cast<float>(rng.uniform(6.0, 30.0));
      float cx = 0, cy = 0, yaw = 0;
      Eigen::Vector3f normal;
      switch (s) {
        case 0:
          cx = bx0 + along;
          cy = by0 + depth;
          normal = {0, -1, 0};
          break;
        case 1:
          cx = bx0 + along;
          cy = by0 + side - depth;
          normal = {0, 1, 0};
          break;
        case 2:
          cx = bx0 + depth;
          cy = by0 + along;
          normal = {-1, 0, 0};
          break;
        default:
          cx = bx0 + side - depth;
          cy = by0 + along;
          normal = {1, 0, 0};
          break;
      }
      if (rng.bernoulli(0.15)) yaw = static_cast<float>(rng.uniform(-0.15, 0.15));
      Eigen::Vector3f half =
          (s < 2) ? Eigen::Vector3f(front, depth, height / 2) : Eigen::Vector3f(depth, front, height / 2);
      const float gz = ground_height(cx, cy);
      const uint32_t label = encode_label(kBuilding, (*instance)++);
      scene->push_back(
          Primitive::box({cx, cy, gz + height / 2}, half, yaw, label, static_cast<float>(rng.uniform(0.2, 0.6))));
      ++*buildings;
      // Roof structure.
      scene->push_back(
          Primitive::box({cx, cy, gz + height + 1.0f}, {half.x() * 0.5f, half.y() * 0.5f, 1.0f}, yaw, label, 0.4f));
      // Facade details (sills, balconies, pillars) on the street-facing facade.
      const Eigen::Vector3f tangent(-normal.y(), normal.x(), 0.0f);
      const float face_off = (s < 2) ? half.y() : half.x();
      const float face_w = (s < 2) ? half.x() : half.y();
      for (int d = 0; d < details_per_building; ++d) {
        const float u = static_cast<float>(rng.uniform(-face_w + 0.6, face_w - 0.6));
        const float z = static_cast<float>(rng.uniform(1.0, height - 0.5));
        const float w = static_cast<float>(rng.uniform(0.3, 1.2));
        const float dh = static_cast<float>(rng.uniform(0.05, 0.6));
        const float proj = static_cast<float>(rng.uniform(0.05, 0.8));
        const Eigen::Vector3f c = Eigen::Vector3f(cx, cy, gz + z) + normal * (face_off + proj) + tangent * u;
        const Eigen::Vector3f h = (s < 2) ? Eigen::Vector3f(w, proj, dh) : Eigen::Vector3f(proj, w, dh);
        scene->push_back(Primitive::box(c, h, yaw, label, 0.5f));
      }
    }
  }
}

// Curbs along the four block edges, a few long, thin, arbitrarily rotated fences and walls
// (large, loose AABBs: the hard case for a BVH) and annexes and sheds in the courtyard.
void add_block_extras(Rng& rng, float bx0, float by0, float side, Scene* scene, uint16_t* instance, int* buildings) {
  // Curbs along the four block edges and a few long, thin, arbitrarily rotated fences
  // and walls (large, loose AABBs: the hard case for a BVH).
  const float edge = side + 4.0f;  // curb at the road edge, around the sidewalk
  const float mx = bx0 + side / 2, my = by0 + side / 2;
  const uint32_t curb = encode_label(kSidewalk, 0);
  scene->push_back(Primitive::box({mx, my - edge / 2, ground_height(mx, my - edge / 2) + 0.07f},
                                  {edge / 2, 0.1f, 0.07f}, 0.0f, curb, 0.3f));
  scene->push_back(Primitive::box({mx, my + edge / 2, ground_height(mx, my + edge / 2) + 0.07f},
                                  {edge / 2, 0.1f, 0.07f}, 0.0f, curb, 0.3f));
  scene->push_back(Primitive::box({mx - edge / 2, my, ground_height(mx - edge / 2, my) + 0.07f},
                                  {0.1f, edge / 2, 0.07f}, 0.0f, curb, 0.3f));
  scene->push_back(Primitive::box({mx + edge / 2, my, ground_height(mx + edge / 2, my) + 0.07f},
                                  {0.1f, edge / 2, 0.07f}, 0.0f, curb, 0.3f));
  for (int k = 0; k < 3; ++k) {
    const float cx = mx + static_cast<float>(rng.uniform(-6.0, 6.0));
    const float cy = my + static_cast<float>(rng.uniform(-6.0, 6.0));
    const float h = static_cast<float>(rng.uniform(1.0, 2.5));
    scene->push_back(Primitive::box(
        {cx, cy, ground_height(cx, cy) + h / 2}, {static_cast<float>(rng.uniform(5.0, 12.0)), 0.05f, h / 2},
        static_cast<float>(rng.uniform(0.0, kPi)), encode_label(51 /* fence */, (*instance)++), 0.35f));
  }
  // Annexes and sheds in the courtyard.
  for (int k = 0; k < 14; ++k) {
    const float cx = bx0 + static_cast<float>(rng.uniform(8.0, side - 8.0));
    const float cy = by0 + static_cast<float>(rng.uniform(8.0, side - 8.0));
    const float h = static_cast<float>(rng.uniform(2.0, 6.0));
    scene->push_back(
        Primitive::box({cx, cy, ground_height(cx, cy) + h / 2},
                       {static_cast<float>(rng.uniform(0.8, 2.5)), static_cast<float>(rng.uniform(0.8, 2.5)), h / 2},
                       static_cast<float>(rng.uniform(0.0, kPi)), encode_label(kBuilding, (*instance)++), 0.4f));
    ++*buildings;
  }
}

// Poles, trees and parked cars along both curbs of every street line.
void add_street_objects(Rng& rng, int blocks, Scene* scene, uint16_t* instance, int* poles, int* trees, int* cars) {
  std::vector<float> lines;
  for (int k = 0; k <= blocks; ++k) lines.push_back(-kHalfSize + k * kBlockPitch);
  for (int dir = 0; dir < 2; ++dir) {
    for (float line : lines) {
      for (int side = -1; side <= 1; side += 2) {
        for (float a = -kHalfSize + 3.0f; a < kHalfSize - 3.0f; a += 1.0f) {
          const float curb = line + side * (kRoadHalfWidth + 0.8f);
          const float x = dir == 0 ? a : curb, y = dir == 0 ? curb : a;
          if (on_road(x, y)) continue;  // crossing
          const double r = rng.uniform();
          const float gz = ground_height(x, y);
          if (r < 0.17) {  // street light / sign pole
            scene->push_back(Primitive::cylinder({x, y, gz}, static_cast<float>(rng.uniform(0.06, 0.15)),
                                                 static_cast<float>(rng.uniform(2.5, 8.0)),
                                                 encode_label(kPole, (*instance)++), 0.6f));
            ++*poles;
          } else if (r < 0.42) {  // tree: trunk + crown
            const float th = static_cast<float>(rng.uniform(2.0, 4.0));
            const uint16_t id = (*instance)++;
            scene->push_back(Primitive::cylinder({x, y, gz}, static_cast<float>(rng.uniform(0.1, 0.3)), th,
                                                 encode_label(kTrunk, id), 0.3f));
            const float cr = static_cast<float>(rng.uniform(1.5, 3.5));
            scene->push_back(Primitive::ellipsoid(
                {x, y, gz + th + cr * 0.8f},
                {cr, cr * static_cast<float>(rng.uniform(0.8, 1.2)), cr * static_cast<float>(rng.uniform(0.9, 1.5))},
                encode_label(kVegetation, id), 0.45f));
            ++*trees;
          }
        }
        // Parked cars in the parking lane (|offset| 4..6 m from the centre line).
        for (float a = -kHalfSize + 4.0f; a < kHalfSize - 4.0f; a += static_cast<float>(rng.uniform(4.8, 7.0))) {
          if (!rng.bernoulli(0.8)) continue;
          const float off = line + side * 5.0f;
          const float x = dir == 0 ? a : off, y = dir == 0 ? off : a;
          const float along = dir == 0 ? x : y;
          const float m = std::fmod(along + kHalfSize, kBlockPitch);
          if (std::min(m, kBlockPitch - m) < kRoadHalfWidth + 1.0f) continue;  // crossing
          if (std::fabs(x) > kHalfSize - 3 || std::fabs(y) > kHalfSize - 3) continue;
          const float yaw = (dir == 0 ? 0.0f : kPi / 2) + static_cast<float>(rng.uniform(-0.08, 0.08));
          const float gz = ground_height(x, y);
          const uint32_t label = encode_label(kCar, (*instance)++);
          scene->push_back(Primitive::box({x, y, gz + 0.75f}, {2.2f, 0.9f, 0.45f}, yaw, label,
                                          static_cast<float>(rng.uniform(0.3, 0.9))));
          scene->push_back(Primitive::box({x, y, gz + 1.45f}, {1.2f, 0.8f, 0.3f}, yaw, label, 0.2f));
          ++*cars;
        }
      }
    }
  }
}

Scene make_city(uint64_t seed, int details_per_building, int* n_buildings) {
  Rng rng(seed);
  Scene scene;
  uint16_t instance = 1;
  add_ground(&scene);
  // Buildings: 10 x 10 blocks of 28 m; 4 street-facing buildings per block side, plus
  // annexes/sheds inside the block, ~30 building boxes per block.
  const int blocks = static_cast<int>(2.0f * kHalfSize / kBlockPitch);
  int buildings = 0;
  for (int bi = 0; bi < blocks; ++bi) {
    for (int bj = 0; bj < blocks; ++bj) {
      const float bx0 = -kHalfSize + bi * kBlockPitch + kRoadHalfWidth + 2.0f;  // sidewalk 2 m
      const float by0 = -kHalfSize + bj * kBlockPitch + kRoadHalfWidth + 2.0f;
      const float side = kBlockPitch - 2.0f * (kRoadHalfWidth + 2.0f);  // 24 m
      add_block_buildings(rng, bx0, by0, side, details_per_building, &scene, &instance, &buildings);
      add_block_extras(rng, bx0, by0, side, &scene, &instance, &buildings);
    }
  }
  int poles = 0, trees = 0, cars = 0;
  add_street_objects(rng, blocks, &scene, &instance, &poles, &trees, &cars);
  std::printf("scene: %d buildings, %d poles, %d trees, %d cars\n", buildings, poles, trees, cars);
  if (n_buildings) *n_buildings = buildings;
  return scene;
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// CPU time of this thread: unaffected by other processes taking the core away.
double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  int scans = 20;
  int details = 36;
  uint64_t seed = 20240611;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> long long {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "missing value for %s\n", arg.c_str());
        std::exit(2);
      }
      return std::atoll(argv[++i]);
    };
    if (arg == "--scans") {
      scans = static_cast<int>(std::max(1LL, value()));
    } else if (arg == "--details") {
      details = static_cast<int>(std::max(0LL, value()));
    } else if (arg == "--seed") {
      seed = static_cast<uint64_t>(value());
    } else {
      std::fprintf(stderr, "usage: %s [--scans N] [--details N] [--seed N]\n", argv[0]);
      return arg == "--help" || arg == "-h" ? 0 : 2;
    }
  }

  auto t0 = Clock::now();
  const Scene scene = make_city(seed, details, nullptr);
  const double gen_s = seconds_since(t0);

  t0 = Clock::now();
  const segmatch::sim::RayCaster caster(scene);
  const double build_s = seconds_since(t0);
  std::printf("primitives: %zu (valid %zu), generation %.1f ms, BVH build %.1f ms\n", scene.size(),
              caster.primitive_count(), gen_s * 1e3, build_s * 1e3);

  const segmatch::sim::LidarModel model = segmatch::sim::hdl64e();
  std::vector<double> times, cpu_times;
  size_t points = 0;
  uint64_t checksum = 1469598103934665603ull;
  for (int k = 0; k < scans; ++k) {
    // Along the street y = 0, in the right lane, heading +x.
    const float x = -150.0f + 300.0f * static_cast<float>(k) / std::max(1, scans - 1);
    const float y = -2.0f;
    segmatch::Pose3d T = segmatch::Pose3d::Identity();
    T.translation() = Eigen::Vector3d(x, y, ground_height(x, y) + model.mount_height_m);
    t0 = Clock::now();
    const double c0 = thread_cpu_seconds();
    const segmatch::sim::SimulatedScan scan =
        segmatch::sim::simulate_scan(caster, model, T, segmatch::mix_seed(seed, k));
    cpu_times.push_back(thread_cpu_seconds() - c0);
    times.push_back(seconds_since(t0));
    points += scan.points.size();
    for (const segmatch::Point& p : scan.points) {  // FNV-1a over the bytes
      unsigned char bytes[sizeof(p)];
      std::memcpy(bytes, &p, sizeof(p));
      for (unsigned char b : bytes) checksum = (checksum ^ b) * 1099511628211ull;
    }
  }
  std::vector<double> sorted = times;
  std::sort(sorted.begin(), sorted.end());
  const double wall = median(times);
  const double cpu = median(cpu_times);
  const double rays = static_cast<double>(model.rays_per_scan());
  std::printf("HDL-64E: %d scans, %zu rays/scan, %.0f returns/scan\n", scans, model.rays_per_scan(),
              static_cast<double>(points) / scans);
  std::printf(
      "scan time: median %.1f ms, min %.1f ms, max %.1f ms (wall); median %.1f ms "
      "(thread CPU)\n",
      wall * 1e3, sorted.front() * 1e3, sorted.back() * 1e3, cpu * 1e3);
  std::printf("median: %.2f scans/s, %.2f Mrays/s (one thread, wall clock)\n", 1.0 / wall, rays / wall / 1e6);
  std::printf("median: %.2f scans/s, %.2f Mrays/s (one thread, CPU time)\n", 1.0 / cpu, rays / cpu / 1e6);
  std::printf("checksum: %016llx\n", static_cast<unsigned long long>(checksum));
  return 0;
}
