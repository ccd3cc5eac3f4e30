#include "segmatch/server/map_service.h"

#include <segmatch/storage/map_reader.h>

#include <chrono>
#include <optional>
#include <stdexcept>

namespace segmatch {
namespace server {
namespace {

constexpr const char* kClassifierFormat = "opencv-rtrees-yaml";

// The map's classifier, or null. Refuses formats this build cannot read.
std::shared_ptr<const RandomForestMatcher> load_classifier(const storage::MapReader& reader) {
  const std::optional<storage::ClassifierBlob> blob = reader.classifier();
  if (!blob) return nullptr;
  if (blob->format != kClassifierFormat)
    throw std::runtime_error(reader.path() + ": classifier format '" + blob->format + "' is not " + kClassifierFormat);
  try {
    return std::make_shared<const RandomForestMatcher>(RandomForestMatcher::load(blob->bytes));
  } catch (const std::exception& e) {
    throw std::runtime_error(reader.path() + ": cannot load the classifier: " + e.what());
  }
}

void fit_extent(LoadedMap& map, const Segments& segments) {
  if (segments.empty()) return;
  map.extent_min = map.extent_max = segments.front().centroid.cast<double>();
  for (const Segment& s : segments) {
    map.extent_min = map.extent_min.cwiseMin(s.centroid.cast<double>());
    map.extent_max = map.extent_max.cwiseMax(s.centroid.cast<double>());
  }
}

}  // namespace

std::shared_ptr<const LoadedMap> load_map(const std::string& path) {
  const storage::MapReader reader = storage::MapReader::open(path);
  auto map = std::make_shared<LoadedMap>();
  map->path = path;
  map->metadata = reader.metadata();
  if (map->metadata.parameters_json.empty())
    throw std::runtime_error(path + ": the map stores no parameters (parameters_json is empty)");
  map->config = io::parse_pipeline_config(map->metadata.parameters_json, path + " (parameters_json)");
  std::shared_ptr<const RandomForestMatcher> classifier = load_classifier(reader);
  MatcherConfig& matcher = map->config.localizer.matcher;
  if (matcher.type == MatcherType::kRandomForest && !classifier) {
    matcher.type = MatcherType::kL2;
    map->fell_back_to_l2 = true;
    map->warnings.push_back(path + ": the parameters ask for the random forest matcher but the map has no "
                            "classifier; serving with the L2 matcher (l2_threshold " +
                            std::to_string(matcher.l2_threshold) + ")");
  }
  if (matcher.type == MatcherType::kRandomForest && classifier->config().use_shapes != matcher.use_shapes)
    throw std::runtime_error(path + ": the classifier was trained with use_shapes=" +
                             (classifier->config().use_shapes ? "true" : "false") + " but the parameters say " +
                             (matcher.use_shapes ? "true" : "false"));
  Segments segments = reader.load_segments();
  fit_extent(*map, segments);
  try {
    map->localizer = std::make_unique<const Localizer>(map->config.localizer, std::move(segments), classifier);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(path + ": cannot build the localizer: " + e.what());
  }
  return map;
}

api::InfoReply info_of(const LoadedMap& map) {
  api::InfoReply info;
  info.map_name = map.metadata.name;
  info.segment_count = map.segment_count();
  info.extent_min = map.extent_min;
  info.extent_max = map.extent_max;
  info.parameters_json = io::to_json(map.config);
  return info;
}

namespace {

PointCloud crop_cylinder(const PointCloud& points, const Eigen::Vector3d& center, double radius_m) {
  const double r2 = radius_m * radius_m;
  PointCloud out;
  out.reserve(points.size());
  for (const Point& p : points) {
    const double dx = p.x - center.x(), dy = p.y - center.y();
    if (dx * dx + dy * dy <= r2) out.push_back(p);
  }
  return out;
}

void copy_timings(const ModuleTimings& t, api::ModuleTimingsMs& out) {
  out.voxel = static_cast<float>(t.voxel_ms), out.ground = static_cast<float>(t.ground_ms);
  out.segment = static_cast<float>(t.segment_ms), out.describe = static_cast<float>(t.describe_ms);
  out.retrieve = static_cast<float>(t.retrieve_ms), out.classify = static_cast<float>(t.classify_ms);
  out.verify = static_cast<float>(t.verify_ms), out.refine = static_cast<float>(t.refine_ms);
  out.total = static_cast<float>(t.total_ms);
}

// A prior with a radius narrows the search (docs/protocol.md 5.4); radius 0 keeps revision 1's
// reject-only meaning (check_prior below).
std::optional<PosePrior> pose_prior_of(const api::LocalizeRequest& request) {
  if (!(request.flags & api::kFlagHasPrior) || !(request.prior_radius_m > 0.0)) return std::nullopt;
  PosePrior prior;
  prior.T_map_query = request.T_map_local_prior;
  prior.radius_m = request.prior_radius_m;
  if (request.flags & api::kFlagPriorHeading) prior.max_rotation_deg = request.prior_heading_tolerance_deg;
  return prior;
}

// With a prior: kOutsidePrior when the localized sensor is too far from the prior's guess.
void check_prior(const api::LocalizeRequest& request, api::LocalizeReply& reply) {
  if (!(request.flags & api::kFlagHasPrior) || reply.status != api::LocalizeStatus::kLocalized) return;
  const Eigen::Vector3d& p_local = request.sensor_position_local;
  const double distance_m = (reply.T_map_local * p_local - request.T_map_local_prior * p_local).norm();
  if (distance_m <= request.prior_radius_m) return;
  reply.status = api::LocalizeStatus::kOutsidePrior;
  reply.reason = "localized " + std::to_string(distance_m) + " m from the prior (search radius " +
                 std::to_string(request.prior_radius_m) + " m)";
}

}  // namespace

api::LocalizeReply localize_request(const LoadedMap& map, const api::LocalizeRequest& request) {
  const auto start = std::chrono::steady_clock::now();
  const PointCloud cloud =
      crop_cylinder(request.points, request.sensor_position_local, map.config.local_cloud.radius_m);
  const CloudKind kind = (request.flags & api::kFlagVoxelized) ? CloudKind::kVoxelized : CloudKind::kRaw;
  const std::optional<PosePrior> prior = pose_prior_of(request);
  const LocalizationResult r =
      map.localizer->localize(cloud, request.sensor_position_local.cast<float>(), kind, prior ? &*prior : nullptr);
  api::LocalizeReply reply;
  reply.request_id = request.request_id;
  reply.status = r.localized()                            ? api::LocalizeStatus::kLocalized
                 : r.refusal == Refusal::kOutsidePrior ? api::LocalizeStatus::kOutsidePrior
                                                       : api::LocalizeStatus::kNotLocalized;
  reply.reason = r.reason;
  reply.T_map_local = r.T_map_query;
  reply.inliers = static_cast<uint32_t>(r.inliers.size());
  reply.confidence = r.confidence;
  reply.support = static_cast<uint32_t>(r.support);
  const Segments& targets = map.localizer->targets();
  for (const Match& m : r.inliers)
    if (m.target >= 0 && static_cast<size_t>(m.target) < targets.size()) reply.matched_segment_ids.push_back(targets[m.target].id);
  copy_timings(r.timings, reply.timings);
  check_prior(request, reply);
  reply.timings.server_total =
      std::chrono::duration<float, std::milli>(std::chrono::steady_clock::now() - start).count();
  return reply;
}

}  // namespace server
}  // namespace segmatch
