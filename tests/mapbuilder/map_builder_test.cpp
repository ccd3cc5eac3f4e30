// MapBuilder on a simulated tiny city, in process: the map holds the objects along the route,
// one segment each, and every segment knows the local cloud it came from.
#include "segmatch/core/mapping/map_builder.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/sim/lidar.h"
#include "segmatch/sim/raycaster.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <memory>
#include <set>
#include <thread>

using namespace segmatch;
using namespace segmatch::sim;

namespace {

constexpr double kRouteM = 120.0;  // enough for several local clouds, short enough to be quick

struct Drive {
  World world;
  Traversal traversal;
};

Drive make_drive(uint64_t seed) {
  const DatasetConfig c = dataset_preset("tiny", seed);
  Drive d{generate_world(c.world), {}};
  Rng rng(mix_seed(seed, 0x7a5e));
  d.traversal = drive(d.world, plan_route(d.world.streets, c.first_length_m, rng), c.drive_first);
  return d;
}

// Feeds every scan up to kRouteM (simulated two at a time) to the builder; scans closer than
// the local cloud's 1 m step are skipped up front since the local cloud would ignore them.
std::vector<size_t> build(MapBuilder& builder, const Drive& d) {
  const RayCaster caster(d.world.scene());
  const Traversal& t = d.traversal;
  std::vector<size_t> frames;
  for (size_t i = 0; i < t.size() && t.odometer_m[i] <= kRouteM; ++i)
    if (frames.empty() || t.odometer_m[i] - t.odometer_m[frames.back()] >= 1.0) frames.push_back(i);
  for (size_t k = 0; k < frames.size(); k += 2) {
    SimulatedScan scans[2];
    const size_t n = std::min<size_t>(2, frames.size() - k);
    std::thread other;
    if (n == 2)
      other = std::thread(
          [&] { scans[1] = simulate_scan(caster, hdl64e(), t.T_world_lidar[frames[k + 1]], frames[k + 1]); });
    scans[0] = simulate_scan(caster, hdl64e(), t.T_world_lidar[frames[k]], frames[k]);
    if (other.joinable()) other.join();
    for (size_t j = 0; j < n; ++j)
      builder.add_scan(scans[j].points, t.T_world_lidar[frames[k + j]], static_cast<uint32_t>(frames[k + j]),
                       &scans[j].labels);
  }
  builder.finish();
  return frames;
}

class MapBuilderOnTinyCity : public ::testing::Test {
 public:
  static void SetUpTestSuite() {
    drive_ = std::make_unique<Drive>(make_drive(3));
    builder_ = std::make_unique<MapBuilder>(MapBuilderConfig{});
    frames_ = build(*builder_, *drive_);
    std::printf("[mapbuilder] %zu scans, %.0f m, %zu local clouds, %zu segments from %zu views\n", frames_.size(),
                builder_->distance_driven_m(), builder_->local_clouds(), builder_->segments().size(),
                builder_->extracted_segments());
  }
  static void TearDownTestSuite() {
    builder_.reset();
    drive_.reset();
  }
  static std::unique_ptr<Drive> drive_;
  static std::unique_ptr<MapBuilder> builder_;
  static std::vector<size_t> frames_;
};
std::unique_ptr<Drive> MapBuilderOnTinyCity::drive_;
std::unique_ptr<MapBuilder> MapBuilderOnTinyCity::builder_;
std::vector<size_t> MapBuilderOnTinyCity::frames_;

// Horizontal distance from (x, y) to the nearest pose of the driven part of the route.
double distance_to_route(const Traversal& t, const Eigen::Vector2f& p) {
  double best = 1e9;
  for (size_t i = 0; i < t.size() && t.odometer_m[i] <= kRouteM; ++i)
    best = std::min(best, (t.T_world_lidar[i].translation().head<2>().cast<float>() - p).cast<double>().norm());
  return best;
}

const char* kind_of(uint16_t instance) {
  for (const WorldObject& o : MapBuilderOnTinyCity::drive_->world.objects)
    if (o.instance == instance) return to_string(o.kind);
  return "?";
}

// One process builds the map once (about a minute of simulation and mapping on a loaded
// 2-core machine; CTest runs every TEST in its own process), then checks each property.
struct Checks : MapBuilderOnTinyCity {
  static void SegmentsEveryMapEveryMetresAndAtTheEnd();
  static void MapHoldsMostTreesPolesAndCarsNearTheRoute();
  static void DuplicateViewsAreMergedIntoOneSegmentPerObject();
  static void EverySegmentComesFromALocalCloudThatContainsIt();
};

}  // namespace

void Checks::SegmentsEveryMapEveryMetresAndAtTheEnd() {
  const double driven = builder_->distance_driven_m();
  ASSERT_GT(driven, kRouteM - 5.0);
  // A cloud each time the odometer passed map_every_m since the last one (overshooting by
  // less than one scan step), plus the final one from finish().
  double max_step_m = 0;
  for (size_t k = 1; k < frames_.size(); ++k)
    max_step_m =
        std::max(max_step_m, drive_->traversal.odometer_m[frames_[k]] - drive_->traversal.odometer_m[frames_[k - 1]]);
  const double every = builder_->config().map_every_m;
  EXPECT_GE(static_cast<double>(builder_->local_clouds()), std::floor(driven / (every + max_step_m)));
  EXPECT_LE(static_cast<double>(builder_->local_clouds()), std::floor(driven / every) + 1);
  EXPECT_FALSE(builder_->finish()) << "nothing new since the last cloud";
  const MapBuilderTimings& t = builder_->timings();
  EXPECT_GT(t.segment_ms, 0.0);
  EXPECT_GT(t.describe_ms, 0.0);
  EXPECT_NEAR(t.total_ms(),
              t.accumulate_ms + t.crop_ms + t.voxel_ms + t.ground_ms + t.segment_ms + t.describe_ms + t.merge_ms, 1e-9);
}

void Checks::MapHoldsMostTreesPolesAndCarsNearTheRoute() {
  std::set<uint16_t> mapped;
  for (const Segment& s : builder_->segments()) mapped.insert(label_instance(s.label));
  std::map<ObjectKind, std::pair<int, int>> found;  // kind -> (mapped, expected)
  for (const WorldObject& o : drive_->world.objects) {
    const bool compact = o.kind == ObjectKind::kTree || o.kind == ObjectKind::kStreetLamp ||
                         o.kind == ObjectKind::kPole || o.kind == ObjectKind::kCar;
    // Within 12 m of the route: on the sidewalks or parked along it, seen up close.
    if (!compact || distance_to_route(drive_->traversal, o.position) > 12.0) continue;
    ++found[o.kind].second;
    found[o.kind].first += mapped.count(o.instance);
  }
  int total_mapped = 0, total = 0;
  for (const auto& [kind, counts] : found) {
    std::printf("[mapbuilder] %-12s %d of %d near the route are in the map\n", to_string(kind), counts.first,
                counts.second);
    total_mapped += counts.first;
    total += counts.second;
  }
  ASSERT_GE(total, 20) << "the route passes enough objects for the test to mean something";
  EXPECT_GE(total_mapped * 10, total * 8) << "at least 80 % of the objects near the route are mapped";
}

void Checks::DuplicateViewsAreMergedIntoOneSegmentPerObject() {
  const Segments& segments = builder_->segments();
  const float d = builder_->config().segment_map.duplicate_distance_m;
  // Each object is seen from many local clouds; the map keeps a fraction of the views.
  EXPECT_GE(builder_->extracted_segments(), 4 * segments.size());
  std::map<uint16_t, std::vector<const Segment*>> by_instance;
  for (const Segment& s : segments)
    if (label_instance(s.label) != 0) by_instance[label_instance(s.label)].push_back(&s);
  for (const auto& [instance, views] : by_instance)
    for (size_t a = 0; a < views.size(); ++a)
      for (size_t b = a + 1; b < views.size(); ++b)
        EXPECT_GE((views[a]->centroid - views[b]->centroid).norm(), d)
            << "instance " << instance << " (" << kind_of(instance)
            << ") has two segments within the duplicate distance";
  std::set<uint64_t> ids;
  for (const Segment& s : segments) ids.insert(s.id);
  EXPECT_EQ(ids.size(), segments.size()) << "segment ids are unique";
}

void Checks::EverySegmentComesFromALocalCloudThatContainsIt() {
  const Segments& segments = builder_->segments();
  const std::vector<uint32_t>& keyframes = builder_->keyframe_of_segment();
  ASSERT_EQ(keyframes.size(), segments.size());
  std::set<uint32_t> distinct(keyframes.begin(), keyframes.end());
  EXPECT_GT(distinct.size(), 5u) << "views come from many local clouds";
  const double radius = builder_->config().local_cloud.radius_m;
  for (size_t i = 0; i < segments.size(); ++i) {
    ASSERT_LT(keyframes[i], drive_->traversal.size());
    ASSERT_TRUE(std::binary_search(frames_.begin(), frames_.end(), keyframes[i])) << "keyframe is a fed scan";
    const Eigen::Vector3d sensor = drive_->traversal.T_world_lidar[keyframes[i]].translation();
    EXPECT_LE((segments[i].centroid.head<2>().cast<double>() - sensor.head<2>()).norm(), radius + 1e-3)
        << "segment " << i << " lies inside the cylinder of its keyframe";
  }
}

TEST_F(MapBuilderOnTinyCity, MapsTheObjectsAlongTheRouteOnceEachWithTheirKeyframes) {
  {
    SCOPED_TRACE("SegmentsEveryMapEveryMetresAndAtTheEnd");
    Checks::SegmentsEveryMapEveryMetresAndAtTheEnd();
  }
  {
    SCOPED_TRACE("MapHoldsMostTreesPolesAndCarsNearTheRoute");
    Checks::MapHoldsMostTreesPolesAndCarsNearTheRoute();
  }
  {
    SCOPED_TRACE("DuplicateViewsAreMergedIntoOneSegmentPerObject");
    Checks::DuplicateViewsAreMergedIntoOneSegmentPerObject();
  }
  {
    SCOPED_TRACE("EverySegmentComesFromALocalCloudThatContainsIt");
    Checks::EverySegmentComesFromALocalCloudThatContainsIt();
  }
}

TEST(MapBuilderConfig, RejectsANonPositiveMappingDistance) {
  MapBuilderConfig c;
  c.map_every_m = 0.0;
  EXPECT_THROW(c.validate(), std::invalid_argument);
  EXPECT_THROW(MapBuilder{c}, std::invalid_argument);
  c.map_every_m = 5.0;
  c.segment_map.duplicate_distance_m = -1.0f;
  EXPECT_THROW(c.validate(), std::invalid_argument);
}

TEST(MapBuilder, OneStationaryScanStillGivesOneLocalCloudOnFinish) {
  MapBuilder builder;
  PointCloud empty;
  EXPECT_FALSE(builder.finish()) << "no scan yet";
  EXPECT_FALSE(builder.add_scan(empty, Pose3d::Identity(), 7));
  EXPECT_TRUE(builder.finish());
  EXPECT_EQ(builder.local_clouds(), 1u);
  EXPECT_TRUE(builder.segments().empty());
}

TEST(MapBuilder, SegmentsEachTimeTheOdometerPassesMapEveryMetres) {
  MapBuilderConfig config;
  config.map_every_m = 5.0;
  MapBuilder builder(config);
  const PointCloud empty;
  std::vector<int> segmented_at;
  for (int x = 0; x <= 22; ++x) {
    Pose3d T_world_sensor = Pose3d::Identity();
    T_world_sensor.translation() = Eigen::Vector3d(x, 0, 0);
    if (builder.add_scan(empty, T_world_sensor, static_cast<uint32_t>(x))) segmented_at.push_back(x);
  }
  EXPECT_EQ(segmented_at, (std::vector<int>{5, 10, 15, 20}));
  EXPECT_DOUBLE_EQ(builder.distance_driven_m(), 22.0);
  EXPECT_TRUE(builder.finish()) << "the last 2 m are segmented too";
  EXPECT_EQ(builder.local_clouds(), 5u);
}
