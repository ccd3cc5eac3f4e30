// segmatch-bench-coldstart: what a cold start costs. Single raw scans of a sequence,
// one every --every-m, each sent alone without a prior (LOCALIZE with the scan as its newest
// scans) to a map loaded in-process, one after another on one thread: the server time per query
// (median, p90), how many localized and by which method, and how long the map's places take to
// describe after it opens (the server answers meanwhile; here they are waited for first).
#include <segmatch/io/sequence.h>
#include <segmatch/server/map_service.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = static_cast<size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace segmatch;
  CLI::App app{"segmatch-bench-coldstart: single raw scans localized without a prior, timed"};
  std::string map_path, sequence;
  double every_m = 10.0;
  size_t max_queries = 60;
  app.add_option("--map", map_path, "map file (segmatch-mapbuilder)")->required();
  app.add_option("--sequence", sequence,
                 "the scans: a sequence folder or bag in the map's frame (e.g. OUT/sequences/00 of segmatch-sim)")
      ->required();
  app.add_option("--every-m", every_m, "one query every this many metres")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app.add_option("--max-queries", max_queries, "at most this many queries")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  try {
    const auto opened = Clock::now();
    const std::shared_ptr<const server::LoadedMap> map = server::load_map(map_path);
    const double open_s = seconds_since(opened);
    const auto described = Clock::now();
    const PlaceIndex* places = map->localizer->places();  // waits for the background description
    const double places_s = seconds_since(described);
    std::printf("map %s: open %.2f s; %zu places described in %.2f s more\n", map_path.c_str(), open_s,
                places ? places->size() : size_t{0}, places_s);
    const io::Sequence seq = io::Sequence::open(sequence);
    std::vector<double> server_ms;
    std::map<std::string, size_t> by_method;
    size_t localized = 0;
    double odometer_m = 0.0, next_m = 0.0;
    for (size_t i = 0; i < seq.size() && server_ms.size() < max_queries; ++i) {
      if (i > 0) odometer_m += (seq.poses()[i].translation() - seq.poses()[i - 1].translation()).norm();
      if (odometer_m < next_m) continue;
      next_m = odometer_m + every_m;
      const Pose3d& T = seq.poses()[i];  // the sequence's frame stands for the vehicle's odometry frame
      api::LocalizeRequest r;
      r.request_id = i;
      r.flags = api::kFlagNewestScans | api::kFlagDetail;
      r.sensor_position_local = T.translation();
      for (Point p : seq.scan(i).points) {
        const Eigen::Vector3d q = T * Eigen::Vector3d(p.x, p.y, p.z);
        p.x = static_cast<float>(q.x()), p.y = static_cast<float>(q.y()), p.z = static_cast<float>(q.z());
        r.points.push_back(p);
      }
      r.newest_points = r.points;
      const api::LocalizeReply reply = server::localize_request(*map, r);
      server_ms.push_back(reply.timings.server_total);
      if (reply.status != api::LocalizeStatus::kLocalized) continue;
      ++localized;
      ++by_method[reply.detail && reply.detail->estimate
                      ? api::to_string(static_cast<api::ReplyMethod>(reply.detail->estimate->method))
                      : "unknown"];
    }
    std::printf(
        "%zu single-scan queries without a prior, %zu localized (not scored: see segmatch-eval localize --single-scan)",
        server_ms.size(), localized);
    for (const auto& [method, n] : by_method) std::printf(", %s %zu", method.c_str(), n);
    std::printf("\nserver time per query: median %.1f ms, p90 %.1f ms (the target: <= 50 ms median on one core)\n",
                quantile(server_ms, 0.5), quantile(server_ms, 0.9));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-bench-coldstart: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
