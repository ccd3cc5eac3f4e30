// Loop closure that closes the loop, end to end with the built tools on a
// simulated closed route (segmatch-sim --route-00 loop) whose odometry drifts as in
// loop_closure_test.cpp (0.3 % long, 0.2 deg / 100 m yaw, 2 mm / m climb): segmatch-loop
// --optimize --scan-edges corrects the trajectory, scale included, and writes every output;
// segmatch-mapbuilder --close-loops (loops only) stores a map on the corrected poses. The
// dataset is simulated once per build.
#include <segmatch/io/pose_io.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/fixture_cache.h"
#include "support/run_command.h"

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace fs = std::filesystem;

namespace {

const std::string kBin = std::string(SEGMATCH_BIN_DIR);

class ClosedRoute : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("segmatch_close_loops_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // Simulated once per build of segmatch-sim (support/fixture_cache.h). Sequence 01 and the
    // labels are not used: the shortest second traversal, no labels.
    const fs::path sim =
        segmatch::test::cached_fixture("closed-route", {kBin + "/segmatch-sim"}, [](const fs::path& out) {
          const auto r = segmatch::test::run_command(
              kBin +
              "/segmatch-sim --preset tiny --seed 3 --route-00 loop --odom-drift-pct 0.3 "
              "--odom-yaw-drift-deg-per-m 0.002 --odom-climb-m-per-m 0.002 --odom-heading-walk 0 --odom-pitch-walk 0 "
              "--no-images --no-labels "
              "--length-01-m 50 --out " +
              out.string());
          if (r.code != 0) throw std::runtime_error("segmatch-sim failed: " + r.output);
        });
    seq_ = (sim / "sequences" / "00").string();
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static fs::path dir_;
  static std::string seq_;
};
fs::path ClosedRoute::dir_;
std::string ClosedRoute::seq_;

}  // namespace

TEST_F(ClosedRoute, LoopOptimizeCorrectsTheDriftedOdometry) {
  const fs::path out = dir_ / "loop";
  const auto r = segmatch::test::run_command(kBin + "/segmatch-loop --input " + seq_ + " --odometry " + seq_ +
                                             "/odom_poses.txt --optimize --scan-edges --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"loops.txt", "loops.g2o", "optimized.g2o", "poses_corrected.txt", "poses_corrected.tum",
                        "odometry.tum", "trajectory.png", "eval.json"})
    EXPECT_GT(fs::file_size(out / f), 0u) << f;
  std::ifstream in(out / "eval.json");
  const nlohmann::json e = nlohmann::json::parse(in);
  EXPECT_EQ(e["false_loops"].get<int>(), 0) << r.output;
  ASSERT_GE(e["true_loops"].get<int>(), 5) << r.output;
  const nlohmann::json& t = e["trajectory"];
  const double before = t["odometry_error"]["rmse_m"], after = t["corrected_error"]["rmse_m"];
  std::printf("[close loops] ATE RMSE %.3f -> %.3f m\n", before, after);
  EXPECT_GT(before, 1.0) << "the odometry must drift";
  EXPECT_LT(after, 0.2) << "the target is <= 0.2 m; the scale error needs the scan edges";
  const nlohmann::json& scans = t["scan_edges"];
  EXPECT_GT(scans["accepted"].get<int>(), 900) << scans.dump();
  EXPECT_EQ(scans["downweighted"].get<int>(), 0) << scans.dump();
  EXPECT_LT(std::abs(scans["step_error"]["median_scale_pct"].get<double>()), 0.2) << scans.dump();
  EXPECT_EQ(t["loop_weights"].size(), e["loops"].get<size_t>());
  EXPECT_EQ(t["downweighted_loops"].size(), 0u) << "every loop here is true";
  EXPECT_GT(t["map"]["duplicates_merged"].get<int>(), 0) << "the revisit's copies merge with the old views";
  // The corrected trajectory files hold one pose per scan.
  std::ifstream kitti(out / "poses_corrected.txt"), tum(out / "poses_corrected.tum");
  size_t kitti_lines = 0, tum_lines = 0;
  for (std::string line; std::getline(kitti, line);) kitti_lines += !line.empty();
  for (std::string line; std::getline(tum, line);) tum_lines += !line.empty() && line[0] != '#';
  EXPECT_EQ(kitti_lines, tum_lines);
  EXPECT_GT(kitti_lines, 900u);
  // The odometry in TUM for evo: the same frames, 8 columns (t x y z qx qy qz qw) a line, and
  // readable back as the poses --odometry / --truth accept.
  std::ifstream odometry(out / "odometry.tum");
  size_t odometry_lines = 0;
  for (std::string line; std::getline(odometry, line);) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream words(line);
    size_t columns = 0;
    for (std::string w; words >> w;) ++columns;
    EXPECT_EQ(columns, 8u) << line;
    ++odometry_lines;
  }
  EXPECT_EQ(odometry_lines, tum_lines);
  EXPECT_EQ(segmatch::io::read_poses((out / "odometry.tum").string()).size(), tum_lines);
}

// Every other scan (--stride 2, a scan every ~1.8 m), which keeps the suite fast: the revisit
// still closes loops (17 when this was written).
TEST_F(ClosedRoute, MapbuilderCloseLoopsStoresTheCorrection) {
  const fs::path map = dir_ / "closed.sqlite";
  const auto r = segmatch::test::run_command(kBin + "/segmatch-mapbuilder --input " + seq_ + " --odometry " + seq_ +
                                             "/odom_poses.txt --close-loops --stride 2 --output " + map.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("closing loops first"), std::string::npos) << r.output;
  const size_t at = r.output.find("\nloops: ");
  ASSERT_NE(at, std::string::npos) << r.output;
  EXPECT_GE(std::stoi(r.output.substr(at + 8)), 5) << "the revisit closes loops";
  const auto info = segmatch::test::run_command(kBin + "/segmatch-mapinfo " + map.string());
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("loop_closure"), std::string::npos) << info.output.substr(0, 2000);
}

TEST_F(ClosedRoute, ScanEdgesNeedTheOptimiser) {
  const auto loop = segmatch::test::run_command(kBin + "/segmatch-loop --input " + seq_ + " --scan-edges --out " +
                                                (dir_ / "never").string());
  EXPECT_EQ(loop.code, 2) << loop.output;
  EXPECT_NE(loop.output.find("--scan-edges needs --optimize"), std::string::npos) << loop.output;
  const auto build = segmatch::test::run_command(kBin + "/segmatch-mapbuilder --input " + seq_ +
                                                 " --scan-edges --output " + (dir_ / "never.sqlite").string());
  EXPECT_EQ(build.code, 2) << build.output;
  EXPECT_NE(build.output.find("--scan-edges needs --close-loops"), std::string::npos) << build.output;
  EXPECT_FALSE(fs::exists(dir_ / "never.sqlite"));
}

TEST_F(ClosedRoute, MapbuilderRefusesAMissingOdometryFile) {
  const auto r = segmatch::test::run_command(kBin + "/segmatch-mapbuilder --input " + seq_ +
                                             " --odometry /nonexistent/odom.txt --close-loops --output " +
                                             (dir_ / "never.sqlite").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("/nonexistent/odom.txt"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "never.sqlite"));
}
