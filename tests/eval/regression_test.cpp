// Regression on a stored map (maps/tiny-3, written by scripts/make-regression-map.sh): today's
// code must read the stored map and give the golden answers for the same queries. The queries
// are not stored: the simulator regenerates them bit for bit from the seed.
#include "segmatch/eval/localization_run.h"
#include "segmatch/server/map_service.h"
#include "segmatch/sim/dataset.h"
#include "segmatch/storage/map_reader.h"
#include "segmatch/storage/map_writer.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <sstream>

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

// One TUM line as evo reads it (numpy.loadtxt): exactly 8 numbers, t tx ty tz qx qy qz qw.
std::vector<double> tum_columns(const std::string& line) {
  std::istringstream in(line);
  std::vector<double> v;
  for (std::string w; in >> w;) v.push_back(std::stod(w));
  return v;
}

// The report's estimated.tum / reference.tum: one line per localized query, the same times in
// both, the estimate and the reference pose of that query.
void expect_trajectories_for_evo(const eval::LocalizationRun& run) {
  const fs::path dir = fs::path(::testing::TempDir()) / "segmatch-regression-report";
  eval::write_localization_report(run, dir.string());
  std::ifstream estimated(dir / "estimated.tum"), reference(dir / "reference.tum");
  ASSERT_TRUE(estimated && reference);
  size_t lines = 0;
  std::string e_line, r_line;
  for (const eval::QueryOutcome& o : run.outcomes) {
    if (!o.localized) continue;
    do std::getline(estimated, e_line);
    while (!e_line.empty() && e_line[0] == '#');
    do std::getline(reference, r_line);
    while (!r_line.empty() && r_line[0] == '#');
    const std::vector<double> e = tum_columns(e_line), r = tum_columns(r_line);
    ASSERT_EQ(e.size(), 8u) << e_line;
    ASSERT_EQ(r.size(), 8u) << r_line;
    EXPECT_EQ(e[0], r[0]) << "the same time in both files";
    EXPECT_NEAR(e[0], o.time_s, 1e-6);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(e[1 + k], o.T_map_sensor.translation()[k], 1e-6);
      EXPECT_NEAR(r[1 + k], o.T_map_sensor_truth.translation()[k], 1e-6);
    }
    const Eigen::Quaterniond q(o.T_map_sensor.linear());  // x y z w on the line, evo's order
    EXPECT_NEAR(std::abs(e[4] * q.x() + e[5] * q.y() + e[6] * q.z() + e[7] * q.w()), 1.0, 1e-6);
    ++lines;
  }
  EXPECT_FALSE(std::getline(estimated, e_line) && !e_line.empty()) << "more lines than localized queries";
  EXPECT_EQ(lines, run.summary.localized);
  fs::remove_all(dir);
}

}  // namespace

// The simulated world of the golden run, generated once for the suite.
class RegressionMap : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    world_ = new fs::path(fs::path(::testing::TempDir()) / "segmatch-regression-tiny-3");
    sim::DatasetConfig dataset = sim::dataset_preset("tiny", 3);
    dataset.first_length_m = kLength00M;
    dataset.second_length_m = kLength01M;
    dataset.write_images = false;
    fs::remove_all(*world_);
    sim::generate_dataset(dataset, world_->string());
  }
  static void TearDownTestSuite() {
    fs::remove_all(*world_);
    delete world_;
  }
  static nlohmann::json golden() {
    std::ifstream golden_file(kMapDir + "/golden.json");
    if (!golden_file) throw std::runtime_error("missing " + kMapDir + "/golden.json (scripts/make-regression-map.sh)");
    return nlohmann::json::parse(golden_file);
  }
  static eval::LocalizationRun replay(const std::string& map_path, const nlohmann::json& golden,
                                      server::MapPoints points = server::MapPoints::kLazy) {
    eval::LocalizationRunConfig config;
    config.map_path = map_path;
    config.sim_dataset = world_->string();
    // The golden answers are the stored map's on clouds built from the exact poses: this test
    // pins the code's answers, not the simulated odometry's drift.
    config.cloud_poses = io::CloudPoses::kReference;
    config.print_each = false;
    const auto& r = golden.at("replay");
    config.replay.every_m = r.at("every_m");
    config.replay.warmup_m = r.at("warmup_m");
    config.replay.first = r.at("first");
    config.replay.last = r.at("last");
    config.replay.stride = r.at("stride");
    server::MapLoadOptions load;
    load.points = points;
    const auto map = server::load_map(config.map_path, load);
    return eval::run_localization(config,
                                  [&](const api::LocalizeRequest& q) { return server::localize_request(*map, q); });
  }
  static fs::path* world_;
};
fs::path* RegressionMap::world_ = nullptr;

TEST_F(RegressionMap, TodaysCodeGivesTheGoldenAnswers) {
  const nlohmann::json golden = RegressionMap::golden();
  const eval::LocalizationRun run = replay(std::string(SEGMATCH_TINY3_MAP), golden);

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
  std::printf(
      "[regression] %zu queries, %zu localized in the golden run, %zu still at the same pose; %zu localized now\n",
      run.outcomes.size(), golden_localized, same, run.summary.localized);
  EXPECT_GE(golden_localized, 3u) << "the golden run should localize: regenerate the map";
  expect_trajectories_for_evo(run);
}

// maps/tiny-3 is a schema-1 file (kept on purpose): upgraded to this build's schema it must
// decode to the same floats, hence give bit-identical answers, in a smaller file; and a server
// reading points lazily must answer as one holding them all in memory.
TEST_F(RegressionMap, UpgradedMapGivesIdenticalAnswers) {
  const nlohmann::json golden = RegressionMap::golden();
  const std::string old_path = std::string(SEGMATCH_TINY3_MAP);
  ASSERT_EQ(storage::MapReader::open(old_path).schema_version(), 1);
  const std::string new_path = (fs::path(::testing::TempDir()) / "segmatch-regression-upgraded.sqlite").string();
  ASSERT_EQ(storage::upgrade_map(old_path, new_path, /*overwrite=*/true), 1);
  EXPECT_EQ(storage::MapReader::open(new_path).schema_version(), storage::kSchemaVersion);
  EXPECT_LT(fs::file_size(new_path) * 3, fs::file_size(old_path)) << "schema 2 should be several times smaller";
  const eval::LocalizationRun before = replay(old_path, golden, server::MapPoints::kMemory);
  for (const server::MapPoints points : {server::MapPoints::kLazy, server::MapPoints::kMemory}) {
    const eval::LocalizationRun after = replay(new_path, golden, points);
    ASSERT_EQ(before.outcomes.size(), after.outcomes.size());
    for (size_t i = 0; i < before.outcomes.size(); ++i) {
      EXPECT_EQ(before.outcomes[i].status, after.outcomes[i].status) << "query " << i;
      EXPECT_EQ(before.outcomes[i].T_map_sensor.matrix(), after.outcomes[i].T_map_sensor.matrix()) << "query " << i;
    }
  }
  fs::remove(new_path);
}
