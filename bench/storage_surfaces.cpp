#include "storage_surfaces.h"

#include <segmatch/storage/lazy_surfaces.h>
#include <segmatch/storage/map_reader.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <unordered_set>

namespace segmatch {
namespace bench {
namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

double terrain(double x, double y) { return 0.8 * std::sin(x / 90.0) + 0.5 * std::cos(y / 70.0); }

// One point per voxel of the layer (voxels keyed by their indices, 21 bits each).
class Voxels {
 public:
  Voxels(float leaf_m, uint32_t seed) : leaf_(leaf_m), rng_(seed) {}
  // Ground keeps its height (with sensor noise); a wall point is its voxel's centroid.
  void add(double x, double y, double z, bool ground) {
    const auto cell = [&](double v) { return static_cast<int64_t>(std::floor(v / leaf_)); };
    const int64_t i = cell(x), j = cell(y), k = cell(z);
    const uint64_t key = uint64_t(i & 0x1FFFFF) << 42 | uint64_t(j & 0x1FFFFF) << 21 | uint64_t(k & 0x1FFFFF);
    if (!seen_.insert(key).second) return;
    std::uniform_real_distribution<double> jitter(-0.05, 0.05);
    std::normal_distribution<double> noise(0.0, 0.01);
    const double cx = (double(i) + 0.5) * leaf_ + jitter(rng_), cy = (double(j) + 0.5) * leaf_ + jitter(rng_);
    const double cz = ground ? z + noise(rng_) : (double(k) + 0.5) * leaf_ + jitter(rng_);
    points_.push_back({float(cx), float(cy), float(cz), 0.f});
  }
  PointCloud take() { return std::move(points_); }

 private:
  double leaf_;
  std::mt19937 rng_;
  std::unordered_set<uint64_t> seen_;
  PointCloud points_;
};

}  // namespace

PointCloud synthetic_surfaces(const std::vector<storage::Keyframe>& trajectory, float leaf_m) {
  Voxels voxels(leaf_m, 3);
  double along = 0.0, last_ground = -1e9;
  for (size_t k = 0; k + 1 < trajectory.size(); ++k) {
    const Eigen::Vector3d a = trajectory[k].T_map_sensor.translation();
    const Eigen::Vector3d b = trajectory[k + 1].T_map_sensor.translation();
    const double length = (b - a).head<2>().norm();
    if (length < 1e-6 || length > 50.0) continue;  // a standstill, or the jump between tiled copies
    const Eigen::Vector2d d = (b - a).head<2>() / length, n(-d.y(), d.x());
    for (double s = 0.0; s < length; s += leaf_m, along += leaf_m) {
      const Eigen::Vector2d p = a.head<2>() + d * s;
      if (along - last_ground >= 10.0) {  // the ground within 30 m, every 10 m
        last_ground = along;
        for (double x = -30.0; x <= 30.0; x += leaf_m)
          for (double y = -30.0; y <= 30.0; y += leaf_m)
            if (x * x + y * y <= 900.0) voxels.add(p.x() + x, p.y() + y, terrain(p.x() + x, p.y() + y), true);
      }
      if (std::fmod(along, 80.0) > 65.0) continue;  // a cross street
      for (double side : {-15.0, 15.0}) {
        const Eigen::Vector2d w = p + n * side;
        for (double z = 0.0; z < 12.0; z += leaf_m) voxels.add(w.x(), w.y(), terrain(w.x(), w.y()) + 0.1 + z, false);
      }
    }
  }
  return voxels.take();
}

void report_surfaces(const std::string& path, double route_km, int runs, double radius_m) {
  std::vector<double> open_ms, index_ms, cold_ms, warm_ms;
  size_t points = 0, tiles_read = 0;
  std::mt19937 rng(11);
  for (int run = 0; run < runs; ++run) {
    auto t = Clock::now();
    auto reader = std::make_shared<const storage::MapReader>(storage::MapReader::open(path));
    open_ms.push_back(ms_since(t));
    t = Clock::now();
    const auto surfaces = std::dynamic_pointer_cast<const storage::LazySurfaces>(storage::make_lazy_surfaces(reader));
    index_ms.push_back(ms_since(t));
    if (!surfaces) {
      std::printf("surface layer: none\n");
      return;
    }
    const std::vector<storage::Keyframe> route = reader->trajectory();
    for (int q = 0; q < 10; ++q) {  // a fresh cache each time: every tile read from the file
      const storage::LazySurfaces lazy(reader);
      const Eigen::Vector3d at = route[rng() % route.size()].T_map_sensor.translation();
      t = Clock::now();
      points = lazy.near(at, radius_m).size();
      cold_ms.push_back(ms_since(t));
      tiles_read = lazy.stats().reads;
      t = Clock::now();
      lazy.near(at, radius_m);
      warm_ms.push_back(ms_since(t));
    }
  }
  const storage::SurfaceLayer layer = *storage::MapReader::open(path).surfaces();
  const double mb = double(layer.stored_bytes) / 1e6;
  std::printf(
      "surface layer: leaf %.2f m, %.0f m tiles: %llu tiles, %llu points, %.1f MB = %.2f MB per km of route "
      "(%.2f bytes a point)\n",
      layer.leaf_m, layer.tile_m, static_cast<unsigned long long>(layer.tile_count),
      static_cast<unsigned long long>(layer.point_count), mb, mb / route_km,
      double(layer.stored_bytes) / double(std::max<uint64_t>(layer.point_count, 1)));
  std::printf(
      "surface layer: open the map %.2f ms, + tile index %.2f ms (medians of %d); near(r = %.0f m) at a "
      "route place: %.2f ms with its tiles read from the file (%zu tiles, %zu points on the last), %.2f ms "
      "from the cache (medians of %zu)\n",
      median(open_ms), median(index_ms), runs, radius_m, median(cold_ms), tiles_read, points, median(warm_ms),
      cold_ms.size());
}

}  // namespace bench
}  // namespace segmatch
