#include "storage_serving.h"

#include <segmatch/storage/lazy_points.h>
#include <segmatch/storage/map_reader.h>

#include <malloc.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <vector>

namespace segmatch {
namespace bench {
namespace {

using server::LoadedMap;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Resident memory of this process (MB) from /proc/self/status: `field` RssAnon (the heap) or
// RssFile (file pages mapped; shared with the page cache and reclaimable).
double resident_mb(const char* field) {
  std::ifstream status("/proc/self/status");
  std::string key;
  double kb = 0;
  while (status >> key) {
    if (key == std::string(field) + ":") {
      status >> kb;
      return kb / 1e3;
    }
    status.ignore(1 << 10, '\n');
  }
  return 0;
}

bool drop_page_cache() {
  ::sync();
  std::ofstream drop("/proc/sys/vm/drop_caches");
  drop << "3\n";
  drop.flush();
  return static_cast<bool>(drop);
}

// A query the map can answer: the map's segments within 25 m of a place, with their
// points, moved into a query frame by a known pose (yaw 20 degrees, 3 m, 1 m): localizing it
// retrieves, classifies, verifies and refines as a vehicle's query does, and refinement reads the
// points of the segments it matched. A tiled city repeats every place in every tile, so the
// query carries a prior (10 m, 10 degrees around the known pose), as a tracked vehicle's does.
struct Query {
  Segments segments;
  Eigen::Vector3f sensor_position;
  Pose3d T_map_query;
};

Query excerpt_query(const storage::MapReader& reader, const Eigen::Vector3f& center) {
  Query q;
  q.T_map_query = Pose3d::Identity();
  q.T_map_query.rotate(Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitZ()));
  q.T_map_query.pretranslate(Eigen::Vector3d(3.0, 1.0, 0.0));
  const Eigen::Affine3f T_query_map = q.T_map_query.inverse().cast<float>();
  q.segments = reader.segments_near(center, 25.f);
  for (Segment& s : q.segments) {
    s.centroid = T_query_map * s.centroid;
    for (Point& p : s.points) {
      const Eigen::Vector3f moved = T_query_map * p.xyz();
      p.x = moved.x(), p.y = moved.y(), p.z = moved.z();
    }
  }
  q.sensor_position = T_query_map * center;
  return q;
}

// Up to `count` points 5 m apart along the trajectory (keyframes in index order).
std::vector<Eigen::Vector3f> route_points(const std::vector<storage::Keyframe>& trajectory, int count) {
  std::vector<Eigen::Vector3f> out;
  double to_next = 0.0;
  for (size_t k = 1; k < trajectory.size() && int(out.size()) < count; ++k) {
    const Eigen::Vector3d a = trajectory[k - 1].T_map_sensor.translation(),
                          b = trajectory[k].T_map_sensor.translation();
    const double length = (b - a).norm();
    if (length > 50.0) continue;  // the jump between two copies of a tiled city
    for (; to_next <= length && int(out.size()) < count; to_next += 5.0)
      out.push_back((a + (b - a) * (length > 0 ? to_next / length : 0.0)).cast<float>());
    to_next -= length;
  }
  return out;
}

QueryFigures run_queries(const LoadedMap& map, std::vector<Query> queries) {
  QueryFigures f;
  const storage::LazyPoints::Stats before = map.lazy_points ? map.lazy_points->stats() : storage::LazyPoints::Stats{};
  std::vector<double> ms;
  for (Query& q : queries) {
    PosePrior prior;
    prior.T_map_query = q.T_map_query;
    const auto s = Clock::now();
    const LocalizationResult r = map.localizer->localize_segments(std::move(q.segments), q.sensor_position, &prior);
    ms.push_back(seconds_since(s) * 1e3);
    f.localized += r.localized();
    f.correct += r.localized() && (r.T_map_query.translation() - q.T_map_query.translation()).norm() < 0.05;
    if (r.localized()) f.pose_sum += r.T_map_query.translation().sum();
  }
  f.queries = static_cast<int>(ms.size());
  if (ms.empty()) return f;
  std::sort(ms.begin(), ms.end());
  f.median_ms = ms[ms.size() / 2];
  f.p90_ms = ms[ms.size() * 9 / 10];
  if (map.lazy_points) {
    f.point_reads = map.lazy_points->stats().reads - before.reads;
    f.cache_hits = map.lazy_points->stats().hits - before.hits;
  }
  return f;
}

ServingFigures measure(const std::string& path, server::MapPoints mode, bool drop_caches) {
  ServingFigures f;
  server::MapLoadOptions options;
  options.points = mode;
  if (drop_caches && !drop_page_cache()) return f;
  const double anon0 = resident_mb("RssAnon"), file0 = resident_mb("RssFile");
  const auto t = Clock::now();
  const auto map = server::load_map(path, options);
  f.open_s = seconds_since(t);
  f.heap_mb = resident_mb("RssAnon") - anon0;
  f.file_mb = resident_mb("RssFile") - file0;

  // The queries are cut from the map before any is timed (the same ones in both modes).
  std::vector<Query> route, random;
  {
    const storage::MapReader reader = storage::MapReader::open(path);
    for (const Eigen::Vector3f& at : route_points(reader.trajectory(), 100)) route.push_back(excerpt_query(reader, at));
    const Segments& targets = map->localizer->targets();
    std::mt19937 rng(11);
    for (int q = 0; q < 100; ++q) random.push_back(excerpt_query(reader, targets[rng() % targets.size()].centroid));
  }
  if (drop_caches && !drop_page_cache()) return f;
  f.route = run_queries(*map, std::move(route));
  f.random = run_queries(*map, std::move(random));
  ::malloc_trim(0);  // the queries' own segments are gone: count what the map keeps
  f.heap_after_mb = resident_mb("RssAnon") - anon0;
  f.file_after_mb = resident_mb("RssFile") - file0;
  f.ok = true;
  return f;
}

}  // namespace

bool can_drop_caches(std::string* why) {
  if (::access("/proc/sys/vm/drop_caches", W_OK) == 0) return true;
  *why = std::string("cannot write /proc/sys/vm/drop_caches: ") + std::strerror(errno);
  return false;
}

ServingFigures open_for_serving(const std::string& path, server::MapPoints mode, bool drop_caches) {
  std::fflush(stdout);
  ::malloc_trim(0);  // the parent's freed loads would otherwise count in the child's memory
  int fds[2];
  if (::pipe(fds) != 0) return {};
  const pid_t child = ::fork();
  if (child == 0) {
    ::close(fds[0]);
    ServingFigures f;
    try {
      f = measure(path, mode, drop_caches);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "open for serving failed: %s\n", e.what());
    }
    const ssize_t written = ::write(fds[1], &f, sizeof(f));
    ::_exit(written == static_cast<ssize_t>(sizeof(f)) ? 0 : 1);
  }
  ::close(fds[1]);
  ServingFigures f;
  const ssize_t got = child > 0 ? ::read(fds[0], &f, sizeof(f)) : -1;
  ::close(fds[0]);
  if (child > 0) ::waitpid(child, nullptr, 0);
  return got == static_cast<ssize_t>(sizeof(f)) ? f : ServingFigures{};
}

}  // namespace bench
}  // namespace segmatch
