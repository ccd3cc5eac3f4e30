// A vehicle tracked over a kilometre with drifting LiDAR-inertial odometry: its local
// clouds are built from segmatch-sim's odom_poses.txt, as on a car, and `--track` feeds each fix
// forward as the next query's prior. A tracker that turned a biased answer into the next prior
// would let the answers drift away from the truth along the route, and away from what the same
// queries get without a prior; neither may happen, and no answer may be false.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/run_command.h"

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

const std::string kBin = SEGMATCH_BIN_DIR;

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

nlohmann::json localize(const fs::path& dir, const std::string& options, const std::string& report) {
  const auto run = segmatch::test::run_command(kBin + "/segmatch-eval localize --quiet --map " +
                                               (dir / "map.sqlite").string() + " --sim " + (dir / "world").string() +
                                               " --every-m 10 " + options + " -o " + (dir / report).string());
  EXPECT_EQ(run.code, 0) << run.output;
  EXPECT_NE(run.output.find("local clouds: the vehicle's odometry"), std::string::npos) << run.output;
  std::ifstream in(dir / report / "localization.json");
  return in ? nlohmann::json::parse(in) : nlohmann::json::object();
}

}  // namespace

TEST(TrackedDrift, AKilometreWithDriftingOdometryKeepsItsErrorsAndNoneIsFalse) {
  const fs::path dir = fs::temp_directory_path() / ("segmatch_tracked_drift_" + std::to_string(getpid()));
  fs::remove_all(dir);
  // 20 m/s: a scan every 2 m, half the scans of the demo's speed for the same streets.
  const auto sim = segmatch::test::run_command(kBin +
                                               "/segmatch-sim --preset demo --seed 1 --speed-mps 20 --length-01-m 1000 "
                                               "--no-labels --no-images --out " +
                                               (dir / "world").string());
  ASSERT_EQ(sim.code, 0) << sim.output;
  const auto built =
      segmatch::test::run_command(kBin + "/segmatch-mapbuilder --input " + (dir / "world/sequences/00").string() +
                                  " --output " + (dir / "map.sqlite").string());
  ASSERT_EQ(built.code, 0) << built.output;
  const nlohmann::json tracked = localize(dir, "--track", "tracked"), global = localize(dir, "", "global");
  fs::remove_all(dir);
  ASSERT_TRUE(tracked.contains("per_query") && global.contains("per_query"));
  EXPECT_EQ(tracked["false_localizations"].get<int>(), 0);
  EXPECT_EQ(global["false_localizations"].get<int>(), 0);

  std::vector<nlohmann::json> fixes;
  size_t mapped = 0;
  for (const auto& q : tracked["per_query"]) {
    mapped += q["mapped"].get<bool>();
    if (q["status"] == "localized") fixes.push_back(q);
  }
  EXPECT_GE(fixes.back()["odometer_m"].get<double>(), 700.0) << "tracked to the end of the drive";
  EXPECT_GE(fixes.size() * 10, mapped * 7) << "at least 70 % of the queries on mapped streets localized";
  // Along the route: the last third's answers are not further off than the first third's.
  const size_t third = fixes.size() / 3;
  std::vector<double> first, last;
  for (size_t i = 0; i < third; ++i) first.push_back(fixes[i]["error_m"].get<double>());
  for (size_t i = fixes.size() - third; i < fixes.size(); ++i) last.push_back(fixes[i]["error_m"].get<double>());
  EXPECT_LE(median(last), median(first) + 0.1) << "tracked errors grow along the route";
  for (const auto& q : fixes) EXPECT_LE(q["error_m"].get<double>(), 0.5) << "frame " << q["frame"];
  // Against the same queries without a prior: tracking does not bias the answers.
  std::map<size_t, double> global_error;
  for (const auto& q : global["per_query"])
    if (q["status"] == "localized") global_error[q["frame"].get<size_t>()] = q["error_m"].get<double>();
  std::vector<double> excess;
  for (const auto& q : fixes) {
    const auto it = global_error.find(q["frame"].get<size_t>());
    if (it != global_error.end()) excess.push_back(q["error_m"].get<double>() - it->second);
  }
  ASSERT_GE(excess.size(), 20u);
  EXPECT_LE(median(excess), 0.03) << "tracked answers further off than the same queries' global ones";
}
