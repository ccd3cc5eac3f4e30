#include "segmatch/core/localization/place_recognition.h"

#include "detail/config_checks.h"
#include "detail/seg_grid.h"
#include "segmatch/core/detail/simd.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace segmatch {

void PlaceRecognitionConfig::validate() const {
  const char* owner = "PlaceRecognitionConfig";
  if (rings < 2 || rings > 200) throw std::invalid_argument("PlaceRecognitionConfig.rings must be in 2..200");
  if (sectors < 8 || sectors > 720) throw std::invalid_argument("PlaceRecognitionConfig.sectors must be in 8..720");
  detail::require_positive(max_radius_m, owner, "max_radius_m");
  detail::require_non_negative(min_height_m, owner, "min_height_m");
  detail::require_positive(max_height_m, owner, "max_height_m");
  if (!(max_height_m > min_height_m))
    throw std::invalid_argument("PlaceRecognitionConfig.max_height_m must exceed min_height_m");
  detail::require_positive(block_height_m, owner, "block_height_m");
  detail::require_positive(place_spacing_m, owner, "place_spacing_m");
  detail::require_positive(lateral_step_m, owner, "lateral_step_m");
  if (lateral_steps < 0 || lateral_steps > 10)
    throw std::invalid_argument("PlaceRecognitionConfig.lateral_steps must be in 0..10");
  if (shortlist < 0) throw std::invalid_argument("PlaceRecognitionConfig.shortlist must be >= 0 (0: every place)");
  if (candidates < 1 || (shortlist > 0 && candidates > shortlist))
    throw std::invalid_argument("PlaceRecognitionConfig.candidates must be in 1..shortlist");
  detail::require_positive(prior_radius_m, owner, "prior_radius_m");
  detail::require_non_negative(heading_tolerance_deg, owner, "heading_tolerance_deg");
  detail::require_fraction(max_distance, owner, "max_distance");
  if (min_support < 0 || min_matched_segments < 0)
    throw std::invalid_argument("PlaceRecognitionConfig.min_support and min_matched_segments must be >= 0");
  detail::require_fraction(min_fitness, owner, "min_fitness");
  detail::require_non_negative(max_shifted_support, owner, "max_shifted_support", "(0: off)");
  detail::require_fraction(fitness_margin, owner, "fitness_margin");
  if (!(map_elevation_min_deg >= -90.0f && map_elevation_max_deg <= 90.0f &&
        map_elevation_min_deg < map_elevation_max_deg))
    throw std::invalid_argument(
        "PlaceRecognitionConfig.map_elevation_min_deg and map_elevation_max_deg must lie in -90..90, min below max");
  detail::require_non_negative(elevation_excess_deg, owner, "elevation_excess_deg");
  detail::require_non_negative(elevation_margin_deg, owner, "elevation_margin_deg");
}

size_t PlaceDescriptor::occupied() const {
  return static_cast<size_t>(std::count_if(cells.begin(), cells.end(), [](float v) { return v > 0.0f; }));
}

double yaw_of(const Pose3d& T) {
  const Eigen::Vector3d x = T.linear().col(0);
  return std::atan2(x.y(), x.x());
}

namespace {

constexpr double kGroundRadiusM = 20.0;  // the ground under the centre: the low points this near
constexpr double kGroundQuantile = 0.05;

double ground_height(const PointCloud& points, const Eigen::Vector3d& centre) {
  std::vector<float> z;
  for (const Point& p : points) {
    const double dx = p.x - centre.x(), dy = p.y - centre.y();
    if (dx * dx + dy * dy <= kGroundRadiusM * kGroundRadiusM) z.push_back(p.z);
  }
  if (z.empty()) return centre.z();
  const size_t k = static_cast<size_t>(kGroundQuantile * static_cast<double>(z.size() - 1));
  std::nth_element(z.begin(), z.begin() + static_cast<std::ptrdiff_t>(k), z.end());
  return z[k];
}

}  // namespace

PlaceDescriptor describe_place(const PointCloud& points, const Eigen::Vector3d& centre, double heading_rad,
                               const PlaceRecognitionConfig& config) {
  PlaceDescriptor d;
  d.rings = config.rings;
  d.sectors = config.sectors;
  d.cells.assign(static_cast<size_t>(d.rings) * d.sectors, 0.0f);
  d.ring_key.assign(static_cast<size_t>(d.rings), 0.0f);
  d.ground_z = ground_height(points, centre);
  const double r_max = config.max_radius_m, two_pi = 2.0 * M_PI;
  const double ring_per_m = d.rings / r_max, sector_per_rad = d.sectors / two_pi;
  for (const Point& p : points) {
    const double dx = p.x - centre.x(), dy = p.y - centre.y();
    const double range = std::sqrt(dx * dx + dy * dy);
    const double h = p.z - d.ground_z;
    if (!(range < r_max) || !(h >= config.min_height_m)) continue;
    double bearing = std::atan2(dy, dx) - heading_rad;
    bearing -= two_pi * std::floor(bearing / two_pi);
    const int ring = std::min(d.rings - 1, static_cast<int>(detail::fast_floor(range * ring_per_m)));
    const int sector = std::min(d.sectors - 1, static_cast<int>(detail::fast_floor(bearing * sector_per_rad)));
    float& cell = d.cells[static_cast<size_t>(ring) * d.sectors + sector];
    cell = std::max(cell, static_cast<float>(std::min<double>(h, config.max_height_m)));
  }
  if (config.occlusion)  // what a scan from the centre sees: behind a cell, only what rises above it
    for (int sector = 0; sector < d.sectors; ++sector) {
      float block = 0.0f;
      for (int ring = 0; ring < d.rings; ++ring) {
        float& cell = d.cells[static_cast<size_t>(ring) * d.sectors + sector];
        if (cell <= block)
          cell = 0.0f;
        else if (cell >= config.block_height_m)
          block = std::max(block, cell);
      }
    }
  for (int ring = 0; ring < d.rings; ++ring) {
    int n = 0;
    for (int s = 0; s < d.sectors; ++s) n += d.cells[static_cast<size_t>(ring) * d.sectors + s] > 0.0f;
    d.ring_key[static_cast<size_t>(ring)] = static_cast<float>(n) / d.sectors;
  }
  return d;
}

PlaceColumns place_columns(const PlaceDescriptor& d) {
  const int R = d.rings, S = d.sectors;
  if (R < 1 || S < 1 || d.cells.size() != static_cast<size_t>(R) * S)
    throw std::invalid_argument("a place descriptor whose cells are not rings x sectors");
  PlaceColumns c;
  c.rings = R;
  c.sectors = S;
  c.values.assign(static_cast<size_t>(R) * S, 0.0f);
  c.occupied.assign(static_cast<size_t>(S), 0.0f);
  for (int s = 0; s < S; ++s) {
    double norm2 = 0.0;
    for (int r = 0; r < R; ++r)
      norm2 += double(d.cells[static_cast<size_t>(r) * S + s]) * d.cells[static_cast<size_t>(r) * S + s];
    if (norm2 <= 0.0) continue;
    c.occupied[static_cast<size_t>(s)] = 1.0f;
    const double inv = 1.0 / std::sqrt(norm2);
    for (int r = 0; r < R; ++r)
      c.values[static_cast<size_t>(s) * R + r] = static_cast<float>(d.cells[static_cast<size_t>(r) * S + s] * inv);
  }
  return c;
}

PlaceDistance place_distance(const PlaceDescriptor& query, const PlaceDescriptor& place) {
  if (query.rings != place.rings || query.sectors != place.sectors)
    throw std::invalid_argument("place descriptors of different shapes compared");
  return place_distance(place_columns(query), place_columns(place));
}

// The distance is 1 - the mean cosine of the columns occupied in both (Kim & Kim, eq. 5). Empty
// columns are zero, so a shift's sum of cosines is one dot product of the query's columns with the
// place's turned by the shift: two contiguous runs, SIMD-friendly (a place in a few microseconds,
// every place of a map in milliseconds).
PlaceDistance place_distance(const PlaceColumns& query, const PlaceColumns& place) {
  if (query.rings != place.rings || query.sectors != place.sectors)
    throw std::invalid_argument("place descriptors of different shapes compared");
  const size_t R = static_cast<size_t>(query.rings), S = static_cast<size_t>(query.sectors);
  const float* q = query.values.data();
  const float* p = place.values.data();
  const float* qo = query.occupied.data();
  const float* po = place.occupied.data();
  PlaceDistance best;
  // Too few shared columns say nothing: a sector in six at least.
  const int min_shared = std::max(1, static_cast<int>(S) / 6);
  for (size_t k = 0; k < S; ++k) {
    const int shared = static_cast<int>(std::lround(simd::dot(qo, po + k, S - k) + simd::dot(qo + S - k, po, k)));
    if (shared < min_shared) continue;
    // query sector j against place sector j + k: j < S - k straight, the rest wrapped around.
    const double sum = double(simd::dot(q, p + k * R, (S - k) * R)) + simd::dot(q + (S - k) * R, p, k * R);
    const double distance = 1.0 - sum / shared;
    if (distance < best.distance) best = {distance, static_cast<int>(k)};
  }
  return best;
}

PlaceIndex::PlaceIndex(const PlaceRecognitionConfig& config) : config_(config) { config_.validate(); }

void PlaceIndex::add(const Pose3d& T_map_sensor, PlaceDescriptor descriptor) {
  if (descriptor.rings != config_.rings || descriptor.sectors != config_.sectors)
    throw std::invalid_argument("a place descriptor of another shape than the index's");
  poses_.push_back(T_map_sensor);
  columns_.push_back(place_columns(descriptor));
  descriptor.cells = {};
  descriptors_.push_back(std::move(descriptor));
}

std::vector<PlaceCandidate> PlaceIndex::query(const PlaceDescriptor& descriptor,
                                              const Eigen::Vector3d& sensor_query) const {
  // Ring keys first when a shortlist is asked for (rotation invariant, a few floats a place),
  // then the full comparison.
  std::vector<size_t> compared(descriptors_.size());
  for (size_t i = 0; i < compared.size(); ++i) compared[i] = i;
  if (config_.shortlist > 0 && compared.size() > static_cast<size_t>(config_.shortlist)) {
    std::vector<std::pair<double, size_t>> by_key;
    by_key.reserve(descriptors_.size());
    for (size_t i = 0; i < descriptors_.size(); ++i) {
      double d2 = 0.0;
      for (size_t r = 0; r < descriptor.ring_key.size(); ++r) {
        const double e = double(descriptor.ring_key[r]) - descriptors_[i].ring_key[r];
        d2 += e * e;
      }
      by_key.emplace_back(d2, i);
    }
    const auto end = by_key.begin() + config_.shortlist;
    std::partial_sort(by_key.begin(), end, by_key.end());
    compared.clear();
    for (auto it = by_key.begin(); it != end; ++it) compared.push_back(it->second);
  }
  const PlaceColumns query_columns = place_columns(descriptor);
  std::vector<std::pair<PlaceDistance, size_t>> scored;
  scored.reserve(compared.size());
  for (size_t i : compared) scored.emplace_back(place_distance(query_columns, columns_[i]), i);
  std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) {
    return a.first.distance != b.first.distance ? a.first.distance < b.first.distance : a.second < b.second;
  });
  std::vector<PlaceCandidate> out;
  const double sector_rad = 2.0 * M_PI / config_.sectors;
  for (const auto& [d, place] : scored) {
    if (out.size() >= static_cast<size_t>(config_.candidates) || d.distance > config_.max_distance) break;
    const Pose3d& P = poses_[place];
    // One candidate per stretch of street: places nearer than a prior's radius are one.
    const bool seen = std::any_of(out.begin(), out.end(), [&](const PlaceCandidate& c) {
      return (poses_[c.place].translation() - P.translation()).head<2>().norm() < config_.prior_radius_m;
    });
    if (seen) continue;
    const double yaw = yaw_of(P) + d.shift_sectors * sector_rad;  // sector j of the query is j + k of the place
    PlaceCandidate c;
    c.place = place;
    c.distance = d.distance;
    c.T_map_query.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Vector3d s = c.T_map_query.linear() * sensor_query;
    c.T_map_query.translation() = Eigen::Vector3d(P.translation().x() - s.x(), P.translation().y() - s.y(),
                                                  descriptors_[place].ground_z - descriptor.ground_z);
    out.push_back(c);
  }
  return out;
}

namespace {

// Between two keyframes farther apart than this the trajectory is not a street driven straight
// (a map of two drives, a gap in the recording): no places are made up along it.
constexpr double kMaxInterpolatedGapM = 100.0;

// The trajectory's poses, and between consecutive ones more than a place spacing apart the poses
// every place_spacing_m along the straight line (yaw turned the shorter way). SLAM keyframes lie
// 5-16 m apart (riverside02's even keyframes: 9.8 m median): places only at keyframes would leave
// a query scan up to half a gap from the nearest, where Scan Context's bins near the sensor no
// longer agree. A trajectory with a pose every metre or two gets no poses added.
std::vector<Pose3d> along_trajectory(const std::vector<Pose3d>& trajectory, double spacing_m) {
  std::vector<Pose3d> out;
  for (size_t i = 0; i < trajectory.size(); ++i) {
    if (i > 0) {
      const Pose3d& a = trajectory[i - 1];
      const Pose3d& b = trajectory[i];
      const double gap = (b.translation() - a.translation()).head<2>().norm();
      const int steps = gap <= kMaxInterpolatedGapM ? static_cast<int>(std::floor(gap / spacing_m)) : 0;
      const double ya = yaw_of(a), turn = std::remainder(yaw_of(b) - ya, 2.0 * M_PI);
      for (int k = 1; k < steps; ++k) {
        const double t = k * spacing_m / gap;
        Pose3d p = Pose3d::Identity();
        p.linear() = Eigen::AngleAxisd(ya + t * turn, Eigen::Vector3d::UnitZ()).toRotationMatrix();
        p.translation() = (1.0 - t) * a.translation() + t * b.translation();
        out.push_back(p);
      }
    }
    out.push_back(trajectory[i]);
  }
  return out;
}

}  // namespace

PlaceIndex build_place_index(const std::vector<Pose3d>& trajectory,
                             const std::function<PointCloud(const Eigen::Vector3d&, double)>& points_near,
                             const PlaceRecognitionConfig& config, const std::atomic<bool>* cancel) {
  PlaceIndex index(config);
  bool first = true;
  Eigen::Vector3d last = Eigen::Vector3d::Zero();
  for (const Pose3d& T : along_trajectory(trajectory, config.place_spacing_m)) {
    if (cancel && cancel->load(std::memory_order_relaxed)) break;
    const Eigen::Vector3d p = T.translation();
    if (!first && (p - last).head<2>().norm() < config.place_spacing_m) continue;
    first = false;
    last = p;
    // The query may drive another lane: places beside the trajectory too, described from the
    // layer there (Scan Context's bins near the sensor change within a couple of metres).
    const double yaw = yaw_of(T);
    const PointCloud near = points_near(p, config.max_radius_m + config.lateral_steps * config.lateral_step_m);
    const Eigen::Vector3d left(-std::sin(yaw), std::cos(yaw), 0.0);
    for (int k = -config.lateral_steps; k <= config.lateral_steps; ++k) {
      Pose3d place = Pose3d::Identity();
      place.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      place.translation() = p + left * (k * config.lateral_step_m);
      index.add(place, describe_place(near, place.translation(), yaw, config));
    }
  }
  return index;
}

PlacesFuture ready_places(std::shared_ptr<const PlaceIndex> places) {
  std::promise<std::shared_ptr<const PlaceIndex>> ready;
  ready.set_value(std::move(places));
  return ready.get_future().share();
}

}  // namespace segmatch
