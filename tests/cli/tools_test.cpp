// Every tool speaks the same command line at its edges: --version names the tool, the
// build's version, the map schema and the protocol; a command-line mistake exits 2; the output
// is -o/--output (old --out still accepted); a server is --server HOST:PORT.
#include "segmatch/cli/tool.h"

#include "support/run_command.h"

#include <gtest/gtest.h>

#include <filesystem>

namespace {

using segmatch::test::run_command;

const char* const kTools[] = {"segmatch-mapbuilder", "segmatch-mapinfo", "segmatch-server", "segmatch-query",
                              "segmatch-eval",       "segmatch-train",   "segmatch-loop",   "segmatch-sim"};

std::string tool_path(const std::string& tool) { return std::string(SEGMATCH_BIN_DIR) + "/" + tool; }

class EveryTool : public ::testing::TestWithParam<const char*> {};

TEST_P(EveryTool, AnswersVersion) {
  const std::string tool = GetParam();
  ASSERT_TRUE(std::filesystem::exists(tool_path(tool))) << tool << " is not built";
  const auto r = run_command(tool_path(tool) + " --version");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.rfind(tool + " ", 0), 0u) << r.output;
  EXPECT_NE(r.output.find("map schema "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("protocol version 1, revision "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\nmodels: "), std::string::npos) << r.output;
}

TEST_P(EveryTool, AWrongFlagExits2) {
  const std::string tool = GetParam();
  ASSERT_TRUE(std::filesystem::exists(tool_path(tool))) << tool << " is not built";
  const auto r = run_command(tool_path(tool) + " --no-such-flag");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("Run with --help"), std::string::npos) << "a message, not a silent exit: " << r.output;
}

INSTANTIATE_TEST_SUITE_P(Tools, EveryTool, ::testing::ValuesIn(kTools),
                         [](const ::testing::TestParamInfo<const char*>& info) {
                           std::string name = info.param;
                           return name.substr(name.find('-') + 1);
                         });

TEST(ToolFlags, RequiredOutputAndServerMistakesExit2) {
  const auto train = run_command(tool_path("segmatch-train"));
  EXPECT_EQ(train.code, 2) << train.output;
  EXPECT_NE(train.output.find("-o/--output is required"), std::string::npos) << train.output;
  const auto loop = run_command(tool_path("segmatch-loop") + " --input somewhere");
  EXPECT_EQ(loop.code, 2) << loop.output;
  EXPECT_NE(loop.output.find("-o/--output is required"), std::string::npos) << loop.output;
  EXPECT_EQ(run_command(tool_path("segmatch-query") + " --server nonsense ping").code, 2);
  EXPECT_EQ(run_command(tool_path("segmatch-query") + " --server host:99999 ping").code, 2);
  const auto eval = run_command(tool_path("segmatch-eval") + " localize --map m --sim w --server nowhere");
  EXPECT_EQ(eval.code, 2) << eval.output;
  EXPECT_NE(eval.output.find("--server wants HOST:PORT"), std::string::npos) << eval.output;
  // The old spellings still parse: an unreachable server is a run-time failure (1), not a mistake.
  EXPECT_EQ(run_command(tool_path("segmatch-query") + " --host 127.0.0.1 --port 1 --timeout-s 1 ping").code, 1);
  EXPECT_EQ(run_command(tool_path("segmatch-query") + " --server 127.0.0.1:1 ping").code, 1);
  const auto help = run_command(tool_path("segmatch-sim") + " --help");
  EXPECT_NE(help.output.find("-o,--output"), std::string::npos) << help.output;
  EXPECT_EQ(help.output.find("--out "), std::string::npos) << "the old spelling is hidden: " << help.output;
}

TEST(ToolFlags, ParseServer) {
  const segmatch::cli::HostPort a = segmatch::cli::parse_server("10.0.0.1:7878");
  EXPECT_EQ(a.host, "10.0.0.1");
  EXPECT_EQ(a.port, 7878);
  EXPECT_EQ(segmatch::cli::parse_server("::1:7001").host, "::1");
  for (const char* bad : {"", "7878", ":7878", "host:", "host:0", "host:65536", "host:12a", "host:1234567"})
    EXPECT_THROW(segmatch::cli::parse_server(bad), std::invalid_argument) << bad;
}

}  // namespace
