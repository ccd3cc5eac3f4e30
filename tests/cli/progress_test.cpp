#include "segmatch/cli/progress.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <string>

using segmatch::cli::Progress;

TEST(Progress, FormatsDurationsForPeople) {
  EXPECT_EQ(Progress::format_duration(0.4), "0 s");
  EXPECT_EQ(Progress::format_duration(59.0), "59 s");
  EXPECT_EQ(Progress::format_duration(185.0), "3 min 05 s");
  EXPECT_EQ(Progress::format_duration(3720.0), "1 h 02 min");
  EXPECT_EQ(Progress::format_duration(-1.0), "?");
}

TEST(Progress, LogOutputEndsWithATotalLine) {
  // A file is not a terminal: no bar, only plain lines, and always a final summary.
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    Progress p("seq 00", 10, "scans", f);
    for (int i = 1; i <= 10; ++i) p.update(static_cast<size_t>(i));
  }
  std::rewind(f);
  char buf[512] = {0};
  const size_t n = std::fread(buf, 1, sizeof buf - 1, f);
  std::fclose(f);
  const std::string out(buf, n);
  EXPECT_NE(out.find("[seq 00] 10/10 scans in"), std::string::npos) << out;
  EXPECT_EQ(out.find('\r'), std::string::npos) << "no carriage returns in logs";
  EXPECT_EQ(out.find("10/10", out.find("10/10") + 1), std::string::npos) << "the total is printed once";
}
