#include "segmatch/server/map_service.h"

#include <segmatch/storage/map_reader.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <optional>
#include <stdexcept>

namespace segmatch {
namespace server {
namespace {

// The map's classifier, or null. Refuses formats this build cannot read.
std::shared_ptr<const RandomForestMatcher> load_classifier(const storage::MapReader& reader) {
  const std::optional<storage::ClassifierBlob> blob = reader.classifier();
  if (!blob) return nullptr;
  if (blob->format != storage::kClassifierFormatRTreesYaml)
    throw std::runtime_error(reader.path() + ": classifier format '" + blob->format + "' is not " +
                             storage::kClassifierFormatRTreesYaml);
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

// The map's places for a cold start (place_recognition.h), described from its surface layer
// along its trajectory in the background (a city's take seconds; the server answers meanwhile):
// none without a layer (schema < 4) or when off. A layer that cannot be read leaves none.
PlacesFuture places_of(const storage::MapReader& reader, std::shared_ptr<const MapSurfaces> surfaces,
                       const PlaceRecognitionConfig& config, std::shared_ptr<std::atomic<bool>> stop) {
  if (!surfaces || !config.enabled) return {};
  std::vector<Pose3d> trajectory;
  for (const storage::Keyframe& k : reader.trajectory()) trajectory.push_back(k.T_map_sensor);
  return std::async(
             std::launch::async,
             [trajectory = std::move(trajectory), surfaces, config, stop]() -> std::shared_ptr<const PlaceIndex> {
               try {
                 return std::make_shared<const PlaceIndex>(build_place_index(
                     trajectory, [&surfaces](const Eigen::Vector3d& c, double r) { return surfaces->near(c, r); },
                     config, stop.get()));
               } catch (const std::exception&) {
                 return nullptr;
               }
             })
      .share();
}

}  // namespace

std::shared_ptr<const LoadedMap> load_map(const std::string& path, const MapLoadOptions& options) {
  const auto shared_reader = std::make_shared<const storage::MapReader>(storage::MapReader::open(path));
  const storage::MapReader& reader = *shared_reader;
  auto map = std::make_shared<LoadedMap>();
  map->path = path;
  map->metadata = reader.metadata();
  map->schema_version = reader.schema_version();
  if (map->metadata.parameters_json.empty())
    throw std::runtime_error(path + ": the map stores no parameters (parameters_json is empty)");
  map->config = io::parse_map_parameters(map->metadata.parameters_json, path + " (parameters_json)");
  if (options.recent_window_m) {
    map->config.localizer.refine.recent_window_m = *options.recent_window_m;
    map->config.localizer.refine.validate();
  }
  if (options.search_enabled) map->config.localizer.search.enabled = *options.search_enabled;
  if (options.segmenter) map->config.localizer.segmentation.segmenter.type = *options.segmenter;
  std::shared_ptr<const RandomForestMatcher> classifier = load_classifier(reader);
  MatcherConfig& matcher = map->config.localizer.matcher;
  if (matcher.type == MatcherType::kRandomForest && !classifier) {
    matcher.type = MatcherType::kL2;
    map->fell_back_to_l2 = true;
    map->warnings.push_back(path +
                            ": the parameters ask for the random forest matcher but the map has no "
                            "classifier; serving with the L2 matcher (l2_threshold " +
                            std::to_string(matcher.l2_threshold) + ")");
  }
  if (matcher.type == MatcherType::kRandomForest && classifier->config().use_shapes != matcher.use_shapes)
    throw std::runtime_error(
        path + ": the classifier was trained with use_shapes=" + (classifier->config().use_shapes ? "true" : "false") +
        " but the parameters say " + (matcher.use_shapes ? "true" : "false"));
  map->segments_digest = api::segments_digest(io::to_json(map->config));
  if (reader.schema_version() < storage::kSchemaVersion)
    map->warnings.push_back(path + ": map schema " + std::to_string(reader.schema_version()) +
                            " (older than this build's " + std::to_string(storage::kSchemaVersion) +
                            "): served as it is; `segmatch-mapinfo --upgrade OLD NEW` rewrites it, smaller");
  const bool lazy = options.points == MapPoints::kLazy;
  Segments segments = lazy ? reader.load_segments_without_points() : reader.load_segments();
  if (lazy) {
    reader.stop_mapping();  // from here on it reads a few segments' points per query
    map->lazy_points = std::make_shared<const storage::LazyPoints>(shared_reader, options.cache_points);
  }
  fit_extent(*map, segments);
  for (const storage::Keyframe& k : reader.trajectory()) map->trajectory.push_back(k.T_map_sensor.translation());
  // The surface layer (schema 4) is always read tile by tile: it is larger than the segments and
  // a query reads one disc of it. Maps without one register the newest scans onto segment points.
  map->surfaces = storage::make_lazy_surfaces(shared_reader, options.cache_points);
  try {
    map->places = places_of(reader, map->surfaces, map->config.localizer.places, map->stop_places);
    map->localizer = std::make_unique<const Localizer>(map->config.localizer, std::move(segments), classifier,
                                                       map->lazy_points, map->surfaces, map->places);
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

void copy_timings(const ModuleTimings& t, api::ModuleTimingsMs& out) {
  out.voxel = static_cast<float>(t.voxel_ms), out.ground = static_cast<float>(t.ground_ms);
  out.segment = static_cast<float>(t.segment_ms), out.describe = static_cast<float>(t.describe_ms);
  out.retrieve = static_cast<float>(t.retrieve_ms), out.classify = static_cast<float>(t.classify_ms);
  out.verify = static_cast<float>(t.verify_ms), out.refine = static_cast<float>(t.refine_ms);
  out.total = static_cast<float>(t.total_ms);
}

// The prior fields of both request kinds, and whether the reply should carry a refusal code.
struct RequestFields {
  bool given = false;
  Pose3d T_map_local = Pose3d::Identity();
  double radius_m = 0.0;
  std::optional<double> heading_tolerance_deg;
  Eigen::Vector3d sensor_local = Eigen::Vector3d::Zero();
  bool refusal_code = false;  // revision 5: LOCALIZE bit 3, LOCALIZE_SEGMENTS bit 2
  bool detail = false;        // revision 6: LOCALIZE bit 4, LOCALIZE_SEGMENTS bit 3
};

RequestFields request_fields(const api::LocalizeRequest& r) {
  RequestFields p{(r.flags & api::kFlagHasPrior) != 0, r.T_map_local_prior, r.prior_radius_m, std::nullopt,
                  r.sensor_position_local};
  if (r.flags & api::kFlagPriorHeading) p.heading_tolerance_deg = r.prior_heading_tolerance_deg;
  p.refusal_code = (r.flags & api::kFlagRefusalCode) != 0;
  p.detail = (r.flags & api::kFlagDetail) != 0;
  return p;
}

RequestFields request_fields(const api::LocalizeSegmentsRequest& r) {
  return {(r.flags & api::kSegmentsFlagHasPrior) != 0,
          r.T_map_local_prior,
          r.prior_radius_m,
          r.prior_heading_tolerance_deg,
          r.sensor_position_local,
          (r.flags & api::kSegmentsFlagRefusalCode) != 0,
          (r.flags & api::kSegmentsFlagDetail) != 0};
}

// A prior with a radius narrows the search (docs/protocol.md 5.4); radius 0 keeps revision 1's
// reject-only meaning (check_prior below).
std::optional<PosePrior> pose_prior_of(const RequestFields& f) {
  if (!f.given || !(f.radius_m > 0.0)) return std::nullopt;
  PosePrior prior;
  prior.T_map_query = f.T_map_local;
  prior.radius_m = f.radius_m;
  if (f.heading_tolerance_deg) prior.max_rotation_deg = *f.heading_tolerance_deg;
  return prior;
}

// With a prior: kOutsidePrior when the localized sensor is too far from the prior's guess.
void check_prior(const RequestFields& f, api::LocalizeReply& reply) {
  if (!f.given || reply.status != api::LocalizeStatus::kLocalized) return;
  const double distance_m = (reply.T_map_local * f.sensor_local - f.T_map_local * f.sensor_local).norm();
  if (distance_m <= f.radius_m) return;
  reply.status = api::LocalizeStatus::kOutsidePrior;
  if (f.refusal_code) reply.refusal = api::RefusalCode::kOutsidePrior;
  reply.reason = "localized " + std::to_string(distance_m) + " m from the prior (search radius " +
                 std::to_string(f.radius_m) + " m)";
}

// The core's refusal as its wire code (docs/protocol.md 6.4). A passed deadline is answered
// with ERROR REQUEST_TIMEOUT before a reply is built.
api::RefusalCode refusal_code_of(Refusal r) {
  switch (r) {
    case Refusal::kNone: return api::RefusalCode::kNone;
    case Refusal::kEmptyMap: return api::RefusalCode::kEmptyMap;
    case Refusal::kTooFewSegments: return api::RefusalCode::kTooFewSegments;
    case Refusal::kNoConsistentMatches: return api::RefusalCode::kNoConsistentMatches;
    case Refusal::kOutsidePrior: return api::RefusalCode::kOutsidePrior;
    case Refusal::kLowSupport: return api::RefusalCode::kLowSupport;
    case Refusal::kAmbiguous: return api::RefusalCode::kAmbiguous;
    case Refusal::kSurfacesDisagree: return api::RefusalCode::kSurfacesDisagree;
    case Refusal::kLowConfidence: return api::RefusalCode::kLowConfidence;
    case Refusal::kOffMap: return api::RefusalCode::kOffMap;
    case Refusal::kNewestScansDisagree: return api::RefusalCode::kNewestScansDisagree;
    case Refusal::kTrackingLost: return api::RefusalCode::kTrackingLost;
    case Refusal::kDeadlinePassed: break;
  }
  return api::RefusalCode::kNone;
}

api::LocalizeReply reply_of(const LoadedMap& map, const LocalizationResult& r, uint64_t request_id,
                            const RequestFields& prior, std::chrono::steady_clock::time_point start) {
  api::LocalizeReply reply;
  reply.request_id = request_id;
  reply.status = r.localized()                         ? api::LocalizeStatus::kLocalized
                 : r.refusal == Refusal::kOutsidePrior ? api::LocalizeStatus::kOutsidePrior
                                                       : api::LocalizeStatus::kNotLocalized;
  reply.reason = r.reason;
  if (prior.refusal_code) reply.refusal = refusal_code_of(r.refusal);
  reply.T_map_local = r.T_map_query;
  reply.inliers = static_cast<uint32_t>(r.inliers.size());
  reply.confidence = r.confidence;
  reply.support = static_cast<uint32_t>(r.support);
  const Segments& targets = map.localizer->targets();
  for (const Match& m : r.inliers)
    if (m.target >= 0 && static_cast<size_t>(m.target) < targets.size())
      reply.matched_segment_ids.push_back(targets[m.target].id);
  copy_timings(r.timings, reply.timings);
  if (!r.localized() && !r.registration_reason.empty())
    reply.reason += " (registration: " + r.registration_reason + ")";
  check_prior(prior, reply);
  if (prior.detail) {
    reply.detail = api::ReplyDetail{r.window_warp_m, r.window_warp_deg, static_cast<uint32_t>(r.window_points), {}};
    api::ReplyDetail::Estimate e;  // revision 7
    e.method = static_cast<uint8_t>(r.method == LocalizationMethod::kRegistration ? api::ReplyMethod::kRegistration
                                    : r.method == LocalizationMethod::kSurfaces   ? api::ReplyMethod::kSurfaces
                                    : r.method == LocalizationMethod::kPlaces     ? api::ReplyMethod::kPlaces
                                                                                  : api::ReplyMethod::kSegments);
    if (reply.status == api::LocalizeStatus::kLocalized) e.covariance_upper = api::covariance_upper(r.covariance);
    reply.detail->estimate = e;
  }
  reply.timings.server_total =
      std::chrono::duration<float, std::milli>(std::chrono::steady_clock::now() - start).count();
  return reply;
}

}  // namespace

namespace {

// The localizer's result for a request; the reply is built by outcome_of.
LocalizationResult localize_cloud(const LoadedMap& map, const api::LocalizeRequest& request, const Deadline& deadline) {
  const PointCloud cloud =
      crop_cylinder(request.points, request.sensor_position_local, map.config.local_cloud.radius_m);
  const CloudKind kind = (request.flags & api::kFlagVoxelized) ? CloudKind::kVoxelized : CloudKind::kRaw;
  const std::optional<PosePrior> prior = pose_prior_of(request_fields(request));
  const Eigen::Vector3f sensor = request.sensor_position_local.cast<float>();
  if ((request.flags & api::kFlagTrack) && prior)  // revision 11: tracking first, on the segments made here
    return map.localizer->localize_tracking_first(cloud, sensor, kind, request.newest_points, *prior, deadline);
  LocalizationResult r = map.localizer->localize(cloud, sensor, kind, prior ? &*prior : nullptr, deadline);
  if ((request.flags & api::kFlagNewestScans) && !deadline.passed())
    map.localizer->refine_to_newest_scans(request.newest_points, sensor, r);
  if (!prior && !r.localized() && r.refusal != Refusal::kDeadlinePassed && !deadline.passed())  // a cold start
    r = map.localizer->recognize_place(std::move(r), cloud, request.newest_points, sensor);
  return r;
}

Outcome outcome_of(const LoadedMap& map, const LocalizationResult& r, uint64_t request_id, const RequestFields& prior,
                   std::chrono::steady_clock::time_point start) {
  if (r.refusal == Refusal::kDeadlinePassed)
    return api::ErrorReply{api::ErrorCode::kRequestTimeout, "request timed out: " + r.reason};
  return reply_of(map, r, request_id, prior, start);
}

}  // namespace

api::LocalizeReply localize_request(const LoadedMap& map, const api::LocalizeRequest& request) {
  const auto start = std::chrono::steady_clock::now();
  return reply_of(map, localize_cloud(map, request, Deadline::never()), request.request_id, request_fields(request),
                  start);
}

Outcome serve_localize(const LoadedMap& map, const api::LocalizeRequest& request, const Deadline& deadline) {
  const auto start = std::chrono::steady_clock::now();
  return outcome_of(map, localize_cloud(map, request, deadline), request.request_id, request_fields(request), start);
}

std::optional<api::ErrorReply> refuse_segments(const LoadedMap& map, const api::LocalizeSegmentsRequest& request) {
  char why[192];
  if (request.parameters_digest != map.segments_digest) {
    std::snprintf(why, sizeof(why),
                  "segments computed with parameters digest %016llx; this map's is %016llx "
                  "(fetch INFO and segment with its parameters)",
                  static_cast<unsigned long long>(request.parameters_digest),
                  static_cast<unsigned long long>(map.segments_digest));
    return api::ErrorReply{api::ErrorCode::kParametersMismatch, why};
  }
  if (map.config.localizer.matcher.needs_esf() && !(request.flags & api::kSegmentsFlagEsf))
    return api::ErrorReply{api::ErrorCode::kParametersMismatch,
                           "this map's matcher compares ESF histograms; the segments carry none (flag bit 1)"};
  return std::nullopt;
}

Outcome serve_localize_segments(const LoadedMap& map, api::LocalizeSegmentsRequest request, const Deadline& deadline) {
  const auto start = std::chrono::steady_clock::now();
  const RequestFields fields = request_fields(request);
  const std::optional<PosePrior> prior = pose_prior_of(fields);
  const Eigen::Vector3f sensor = request.sensor_position_local.cast<float>();
  // Tracking on the surface layer first (revision 11, docs/protocol.md 5.5); the full request's
  // path when it does not answer and the segments carry points, TRACKING_LOST when they do not.
  std::string tracking_reason;  // why tracking did not answer, for the full path's refusal
  if (request.flags & api::kSegmentsFlagTrack) {
    const bool has_points = std::any_of(request.segments.begin(), request.segments.end(),
                                        [](const Segment& s) { return !s.points.empty(); });
    LocalizationResult tracked;
    if (prior) {
      tracked = map.localizer->track(std::move(request.segments), request.newest_points, sensor, *prior);
      if (!tracked.localized()) request.segments = std::move(tracked.query);  // a refusal keeps them, for the full path
    } else {
      tracked.refusal = Refusal::kTrackingLost,
      tracked.reason = "tracking on the surface layer needs a prior radius > 0";
    }
    if (tracked.localized() || !has_points) return outcome_of(map, tracked, request.request_id, fields, start);
    tracking_reason = std::move(tracked.reason);
  }
  LocalizationResult r =
      map.localizer->localize_segments(std::move(request.segments), sensor, prior ? &*prior : nullptr, {}, deadline);
  if ((request.flags & api::kSegmentsFlagNewestScans) && !deadline.passed())  // revision 10, as LOCALIZE bit 5
    map.localizer->refine_to_newest_scans(request.newest_points, sensor, r);
  if (!prior && !r.localized() && r.refusal != Refusal::kDeadlinePassed && !deadline.passed() &&
      !request.newest_points.empty())  // a cold start, from the newest scans alone
    r = map.localizer->recognize_place(std::move(r), {}, request.newest_points, sensor);
  keep_tracking_reason(tracking_reason, r);
  return outcome_of(map, r, request.request_id, fields, start);
}

api::LocalizeReply localize_segments_request(const LoadedMap& map, api::LocalizeSegmentsRequest request) {
  return std::get<api::LocalizeReply>(serve_localize_segments(map, std::move(request), Deadline::never()));
}

}  // namespace server
}  // namespace segmatch
