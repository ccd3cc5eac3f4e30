// Regression on a stored map (maps/tiny-3, written by scripts/make-regression-map.sh): today's
// code must read the stored map and give the golden answers for the same queries. The queries
// are not stored: the simulator regenerates them bit for bit from the seed.
#include "segmatch/eval/localization_run.h"
#include "segmatch/server/map_service.h"
#include "segmatch/sim/dataset.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

const std::string kMapDir = SEGMATCH_SOURCE_DIR "/maps/tiny-3";
constexpr double kLength00M = 250.0, kLength01M = 200.0;  // as scripts/make-regression-map.sh
constexpr double kTranslationToleranceM = 0.05, kRotationToleranceDeg = 0.25;

Pose3d pose_of(const nlohmann::json& j) {
  Pose3d T = Pose3d::Identity();
  const auto& q = j.at("q_wxyz");
  T.linear() = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  T.translation() << j.at("t")[0], j.at("t")[1], j.at("t")[2];
  return T;
}

}  // namespace

TEST(RegressionMap, TodaysCodeGivesTheGoldenAnswers) {
  std::ifstream golden_file(kMapDir + "/golden.json");
  ASSERT_TRUE(golden_file) << "missing " << kMapDir << "/golden.json (scripts/make-regression-map.sh)";
  const nlohmann::json golden = nlohmann::json::parse(golden_file);

  const fs::path world = fs::path(::testing::TempDir()) / "segmatch-regression-tiny-3";
  sim::DatasetConfig dataset = sim::dataset_preset("tiny", 3);
  dataset.first_length_m = kLength00M;
  dataset.second_length_m = kLength01M;
  dataset.write_images = false;
  fs::remove_all(world);
  sim::generate_dataset(dataset, world.string());

  eval::LocalizationRunConfig config;
  config.map_path = kMapDir + "/map.sqlite";
  config.sim_dataset = world.string();
  config.print_each = false;
  const auto& r = golden.at("replay");
  config.replay.every_m = r.at("every_m");
  config.replay.warmup_m = r.at("warmup_m");
  config.replay.first = r.at("first");
  config.replay.last = r.at("last");
  config.replay.stride = r.at("stride");
  const auto map = server::load_map(config.map_path);
  const eval::LocalizationRun run =
      eval::run_localization(config, [&](const api::LocalizeRequest& q) { return server::localize_request(*map, q); });
  fs::remove_all(world);

  const auto& expected = golden.at("per_query");
  ASSERT_EQ(run.outcomes.size(), expected.size()) << "the replay no longer yields the golden queries";
  size_t golden_localized = 0, same = 0;
  for (size_t i = 0; i < expected.size(); ++i) {
    const eval::QueryOutcome& now = run.outcomes[i];
    ASSERT_EQ(now.frame, expected[i].at("frame").get<size_t>());
    EXPECT_TRUE(!now.localized || now.correct) << "frame " << now.frame << ": a false localization";
    if (!expected[i].contains("T_map_sensor")) continue;
    ++golden_localized;
    if (!now.localized) {
      ADD_FAILURE() << "frame " << now.frame << " was localized in the golden run and is not now";
      continue;
    }
    const Pose3d before = pose_of(expected[i].at("T_map_sensor"));
    const double dt = (before.translation() - now.T_map_sensor.translation()).norm();
    const double dr = Eigen::AngleAxisd(before.linear().transpose() * now.T_map_sensor.linear()).angle() * 180.0 / M_PI;
    EXPECT_LE(dt, kTranslationToleranceM) << "frame " << now.frame;
    EXPECT_LE(dr, kRotationToleranceDeg) << "frame " << now.frame;
    same += dt <= kTranslationToleranceM && dr <= kRotationToleranceDeg;
  }
  std::printf("[regression] %zu queries, %zu localized in the golden run, %zu still at the same pose; %zu localized now\n",
              run.outcomes.size(), golden_localized, same, run.summary.localized);
  EXPECT_GE(golden_localized, 3u) << "the golden run should localize: regenerate the map";
}
