// segmatch-loop end to end on hku-loop1 with no preset and no loop option: the auto
// profile measures the recording as narrow-fov and brings that class's loop settings, every
// output file is written, the revisit is detected and no loop is false. And a missing input folder is refused by name.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/run_command.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

namespace {

const std::string kBin = std::string(SEGMATCH_BIN_DIR) + "/segmatch-loop";
const std::string kHku = std::string(SEGMATCH_SHARED_DATA_DIR) + "/real/hku-loop1";

segmatch::test::CommandResult run(const std::string& args) { return segmatch::test::run_command(kBin + " " + args); }

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("segmatch_loop_cli_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(d);
  return d;
}

}  // namespace

TEST(LoopCli, DefaultProfileDetectsTheHkuRevisit) {
  if (!fs::exists(kHku)) GTEST_SKIP() << kHku << " is absent (real data is not in the repository)";
  const fs::path out = fresh_dir("hku");
  const auto r = run("--input " + kHku + " --odometry " + kHku + "/odom_poses.txt --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("sensor class: narrow-fov"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("auto loop settings: a local cloud every 1.0 m"), std::string::npos) << r.output;
  for (const char* f : {"loops.txt", "loops.g2o", "loops.png", "eval.json", "precision_recall.png"})
    EXPECT_GT(fs::file_size(out / f), 0u) << f;
  std::ifstream in(out / "eval.json");
  const nlohmann::json e = nlohmann::json::parse(in);
  EXPECT_EQ(e["false_loops"].get<int>(), 0) << r.output;
  EXPECT_GE(e["detected_revisit_local_clouds"].get<int>(), 1) << r.output;
  EXPECT_EQ(e["curve"].size(), 7u);
  fs::remove_all(out);
}

TEST(LoopCli, MissingInputFolderIsRefusedByName) {
  const fs::path out = fresh_dir("missing");
  const auto r = run("--input /nonexistent/sequence --preset livox-keyframes --out " + out.string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("/nonexistent/sequence"), std::string::npos) << r.output;
  fs::remove_all(out);
}
