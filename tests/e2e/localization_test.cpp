// End to end on simulated cities: a map from one traversal, queries from the revisit (other
// scans, another lane, the other direction, moved cars) with the shipped classifier and with one
// trained here on another city, and queries from a city the map never saw.
#include "segmatch/core/localization/localizer.h"
#include "segmatch/core/mapping/segment_map.h"
#include "segmatch/core/training/training.h"
#include "segmatch/sim/city.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <memory>
#include <stdexcept>

using namespace segmatch;
using namespace segmatch::sim;

namespace {

// Segments of the voxelized local clouds (as the map builder keeps them) every `every_m` along
// a traversal, in the world frame, labelled; views of one object merged as in a map.
Segments map_along(const World& world, const Traversal& t, double every_m, const SegmentationConfig& config,
                   uint64_t seed) {
  SegmentsAlongConfig along;
  along.schedule.every_m = every_m;
  along.schedule.seed = seed;
  along.segmentation = config;
  return segments_along(world, t, hdl64e(), along);
}

// The classifier learns from other cities than the one it is tested on, as a user's model
// trained on one recording must work on another.
std::shared_ptr<RandomForestMatcher> train_on(const std::vector<uint64_t>& seeds, const LocalizerConfig& config) {
  std::vector<std::unique_ptr<LabelledCity>> cities;  // the pairs point into these
  std::vector<std::pair<const Segment*, const Segment*>> pairs;
  std::vector<bool> same_object;
  SegmentsAlongConfig along;
  along.segmentation = config.segmentation;
  for (uint64_t seed : seeds) {
    cities.push_back(labelled_city(dataset_preset("tiny", seed), hdl64e(), along, TrainingPairConfig{}));
    const TrainingPairs& p = cities.back()->pairs;
    pairs.insert(pairs.end(), p.pairs.begin(), p.pairs.end());
    same_object.insert(same_object.end(), p.same_object.begin(), p.same_object.end());
  }
  auto rf = std::make_shared<RandomForestMatcher>(config.matcher);
  rf->train(pairs, same_object);
  const size_t positives = static_cast<size_t>(std::count(same_object.begin(), same_object.end(), true));
  std::printf("[e2e] classifier trained on %zu positives, %zu negatives\n", positives, pairs.size() - positives);
  return rf;
}

// The classifier the product ships (maps/models/default-rf.yml, segmatch-train on the simulated
// cities 101-103, 105 and 106): it never saw city 3 or 104.
std::shared_ptr<RandomForestMatcher> shipped_classifier() {
  std::ifstream in(SEGMATCH_DEFAULT_MODEL, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read the shipped classifier " SEGMATCH_DEFAULT_MODEL);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return std::make_shared<RandomForestMatcher>(RandomForestMatcher::load(bytes));
}

struct Outcome {
  size_t queries = 0, localized = 0, accurate = 0, false_positives = 0;
  std::vector<double> errors_m, errors_deg;
};

// Queries the map with voxelized local clouds along a traversal (a vehicle's VoxelAccumulator,
// CloudKind::kVoxelized), expressed in the vehicle's odometry frame (its first pose), and
// scores them against the ground truth.
Outcome query_along(const Localizer& localizer, const World& world, const Traversal& t, uint64_t seed) {
  const RayCaster caster(world.scene());
  const Pose3d T_query_world = t.T_world_lidar.front().inverse();
  Outcome o;
  LocalCloudSchedule schedule;
  schedule.every_m = 10.0;
  schedule.seed = seed;
  // Exact simulated poses: nothing drifts, so no age limit (it is there for a vehicle's odometry
  // and would only thin these clouds: docs/how-defaults-were-chosen.md).
  for_each_voxelized_cloud(
      caster, hdl64e(), t, without_age_limit(LocalCloudConfig{}), localizer.config().segmentation.voxel, schedule,
      [&](const SimulatedLocalCloud& lc) {
        PointCloud cloud = lc.cloud;
        for (Point& p : cloud) {
          const Eigen::Vector3f q = T_query_world.cast<float>() * p.xyz();
          p.x = q.x(), p.y = q.y(), p.z = q.z();
        }
        const Pose3d T_query_sensor = T_query_world * lc.T_world_sensor;
        const LocalizationResult r =
            localizer.localize(cloud, T_query_sensor.translation().cast<float>(), CloudKind::kVoxelized);
        ++o.queries;
        std::printf(
            "[e2e]   frame %4zu: %3zu segments, %5zu candidates, %4zu matches, %2zu inliers, support %2zu/%2zu: %s "
            "%s\n",
            lc.frame, r.query_segments, r.candidates, r.matches, r.inliers.size(), r.support, r.runner_up_support,
            to_string(r.status), r.reason.c_str());
        if (!r.localized()) return;
        ++o.localized;
        const Pose3d T_map_sensor = r.T_map_query * T_query_sensor;  // map frame = world frame
        const double err_m = (T_map_sensor.translation() - lc.T_world_sensor.translation()).norm();
        const double err_deg =
            Eigen::AngleAxisd(T_map_sensor.linear().transpose() * lc.T_world_sensor.linear()).angle() * 180.0 / M_PI;
        o.errors_m.push_back(err_m);
        o.errors_deg.push_back(err_deg);
        o.accurate += err_m <= 0.2 && err_deg <= 1.0;
        o.false_positives += err_m > 1.0 || err_deg > 3.0;
      });
  return o;
}

class EndToEnd : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    city_ = std::make_unique<City>(make_city(dataset_preset("tiny", 3)));
    classifier_ = shipped_classifier();
    other_city_ = std::make_unique<City>(make_city(dataset_preset("tiny", 104)));
    localizer_ = std::make_unique<Localizer>(
        config_, map_along(city_->world, city_->first, 5.0, config_.segmentation, 21), classifier_);
    std::printf("[e2e] map: %zu segments\n", localizer_->targets().size());
  }
  static void TearDownTestSuite() {
    localizer_.reset();
    city_.reset();
    other_city_.reset();
  }
  static LocalizerConfig config_;
  static std::unique_ptr<City> city_, other_city_;
  static std::shared_ptr<RandomForestMatcher> classifier_;
  static std::unique_ptr<Localizer> localizer_;
};
LocalizerConfig EndToEnd::config_;
std::unique_ptr<City> EndToEnd::city_, EndToEnd::other_city_;
std::shared_ptr<RandomForestMatcher> EndToEnd::classifier_;
std::unique_ptr<Localizer> EndToEnd::localizer_;

}  // namespace

TEST_F(EndToEnd, RevisitIsLocalizedWithinTwentyCentimetresAndOneDegree) {
  const Outcome o = query_along(*localizer_, city_->changed, city_->second, 31);
  std::vector<double> e = o.errors_m;
  std::sort(e.begin(), e.end());
  std::printf("[e2e] revisit: %zu queries, %zu localized, %zu within 0.2 m / 1 deg, %zu false; median error %.3f m\n",
              o.queries, o.localized, o.accurate, o.false_positives, e.empty() ? NAN : e[e.size() / 2]);
  ASSERT_GE(o.queries, 10u);
  EXPECT_EQ(o.false_positives, 0u);
  EXPECT_GE(o.accurate * 10, o.queries * 6) << "most queries localize accurately";
}

// The training path end to end: a classifier trained here on one other city (labelled pairs from
// its two traversals, ~500 positives) localizes part of the revisit, never falsely. It is weaker
// than the shipped one (5 cities): 6 of 13 accurate against 9 when this was written.
TEST_F(EndToEnd, AClassifierTrainedOnAnotherCityLocalizesTheRevisit) {
  const Localizer localizer(config_, localizer_->targets(), train_on({101}, config_));
  const Outcome o = query_along(localizer, city_->changed, city_->second, 31);
  std::printf("[e2e] trained on city 101: %zu queries, %zu localized, %zu accurate, %zu false\n", o.queries,
              o.localized, o.accurate, o.false_positives);
  ASSERT_GE(o.queries, 10u);
  EXPECT_EQ(o.false_positives, 0u);
  EXPECT_GE(o.accurate * 5, o.queries * 2) << "at least 40 % of the queries localize accurately";
}

TEST_F(EndToEnd, QueriesFromStreetsNotInTheMapAreRefused) {
  // Local clouds of another city: no street of it is in the map.
  const Outcome o = query_along(*localizer_, other_city_->world, other_city_->first, 41);
  std::printf("[e2e] unmapped: %zu queries, %zu localized\n", o.queries, o.localized);
  ASSERT_GE(o.queries, 10u);
  EXPECT_EQ(o.localized, 0u);
}
