// A segment map ready to serve: opened with storage::MapReader, its parameters parsed
// (io::parse_pipeline_config on the map's parameters_json), its classifier loaded, and a
// Localizer built over its segments. Immutable once loaded, so any number of threads may
// localize against one LoadedMap at once.
//
// Matcher fallback: when the map's parameters ask for the random forest but the map stores no
// classifier, the map is served with the L2 matcher (MatcherConfig::l2_threshold) and a
// warning is recorded in `warnings` (segmatch-server prints it). L2 localizes less often than
// a trained forest but never needs one; refusing to start would leave vehicles with nothing.
#pragma once

#include <segmatch/api/protocol.h>
#include <segmatch/core/localization/localizer.h>
#include <segmatch/io/pipeline_config.h>
#include <segmatch/storage/lazy_points.h>
#include <segmatch/storage/lazy_surfaces.h>
#include <segmatch/storage/map_types.h>

#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace segmatch {
namespace server {

struct LoadedMap {
  std::string path;
  storage::MapMetadata metadata;
  io::PipelineConfig config;                             // as served (after the L2 fallback, if any)
  Eigen::Vector3d extent_min = Eigen::Vector3d::Zero();  // bbox of the segment centroids (map frame)
  Eigen::Vector3d extent_max = Eigen::Vector3d::Zero();
  std::unique_ptr<const Localizer> localizer;  // targets in map order; targets()[i].id = map id
  bool fell_back_to_l2 = false;
  // api::segments_digest of the parameters JSON that INFO_REPLY sends: LOCALIZE_SEGMENTS
  // requests must name it.
  uint64_t segments_digest = 0;
  std::vector<std::string> warnings;
  std::shared_ptr<const storage::LazyPoints> lazy_points;  // kLazy: the localizer's point source
  std::shared_ptr<const MapSurfaces> surfaces;             // the map's surface layer, read lazily (null: none)
  // The map's places for cold starts, described from the layer in the background from load on
  // (invalid: none); set `stop_places` to stop that early.
  PlacesFuture places;
  std::shared_ptr<std::atomic<bool>> stop_places = std::make_shared<std::atomic<bool>>(false);
  LoadedMap() = default;
  LoadedMap(const LoadedMap&) = delete;
  LoadedMap& operator=(const LoadedMap&) = delete;
  ~LoadedMap() { stop_places->store(true); }  // a map dropped at once does not wait for its places
  int schema_version = 0;                     // of the map file as read (an old one is served as it is)
  // The sensor positions of the mapping traversal's keyframes (map frame; empty when the map
  // stores none): the operator's page draws them.
  std::vector<Eigen::Vector3d> trajectory;
  size_t segment_count() const { return localizer ? localizer->targets().size() : 0; }
};

// Where a served map's segment points live. kLazy (the default): in the map file, read when a
// query's refinement needs them (storage::LazyPoints, a bounded cache); the server holds only
// what retrieval, classification and verification read, and opens a city map in a fraction of
// the time. kMemory: every point loaded at start, as before. Both give the same answers.
enum class MapPoints { kLazy, kMemory };
struct MapLoadOptions {
  MapPoints points = MapPoints::kLazy;
  size_t cache_points = 2'000'000;  // kLazy: points kept cached (16 bytes each)
  // Serve with this refine.recent_window_m instead of the map's (a what-if on a stored map:
  // segmatch-eval localize --recent-window-m). Empty: the map's.
  std::optional<float> recent_window_m;
  // Serve with the wide-prior search (search.enabled) on or off instead of as the map says (a
  // what-if: segmatch-eval localize --search off). Empty: the map's.
  std::optional<bool> search_enabled;
  // Segment the queries' clouds with this segmenter instead of the map's (a what-if: segmatch-eval
  // localize / funnel --segmenter range_image). The map's own segments stay as they were built.
  std::optional<SegmenterType> segmenter;
};

// Throws (storage::StorageError, io::IoError or std::runtime_error, each naming the file) when
// the map cannot be read, has no parameters, a classifier of an unknown format or one that
// disagrees with the parameters (use_shapes).
std::shared_ptr<const LoadedMap> load_map(const std::string& path, const MapLoadOptions& options = {});

api::InfoReply info_of(const LoadedMap& map);

// One LOCALIZE: keeps the points within local_cloud.radius_m (horizontal) of the sensor,
// localizes them, and with a prior refuses (kOutsidePrior, the pose still reported) a pose
// that puts the sensor farther than prior_radius_m from where T_map_local_prior puts it.
// Throws only what the localizer throws (a bug, reported to the client as kInternal).
api::LocalizeReply localize_request(const LoadedMap& map, const api::LocalizeRequest& request);

// LOCALIZE_SEGMENTS (docs/protocol.md 5.5): why the map cannot take these segments
// (kParametersMismatch: another digest, or no ESF where the map's matcher needs it), if so.
std::optional<api::ErrorReply> refuse_segments(const LoadedMap& map, const api::LocalizeSegmentsRequest& request);

// The same as localize_request from the vehicle's segments: the Localizer's steps after
// description, on segments accepted by refuse_segments.
// Takes the request by value: a caller done with it moves its segments in.
api::LocalizeReply localize_segments_request(const LoadedMap& map, api::LocalizeSegmentsRequest request);

// What the server answers a request: its reply, or ERROR kRequestTimeout when `deadline`
// passed before the localizer finished (it stops between stages: core/deadline.h).
using Outcome = std::variant<api::LocalizeReply, api::ErrorReply>;
Outcome serve_localize(const LoadedMap& map, const api::LocalizeRequest& request, const Deadline& deadline);
Outcome serve_localize_segments(const LoadedMap& map, api::LocalizeSegmentsRequest request, const Deadline& deadline);

}  // namespace server
}  // namespace segmatch
