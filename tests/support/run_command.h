// Runs a command line as a user would (a shell, stderr folded into stdout) for the tests of
// the command-line tools.
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace segmatch::test {

struct CommandResult {
  int code = -1;       // exit status; -1 if the command could not start or did not exit
  std::string output;  // stdout and stderr
};

inline CommandResult run_command(const std::string& command_line) {
  CommandResult r;
  FILE* pipe = popen((command_line + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buffer[4096];
  for (size_t n; (n = fread(buffer, 1, sizeof buffer, pipe)) > 0;) r.output.append(buffer, n);
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace segmatch::test
