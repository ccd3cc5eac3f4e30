// What every command-line tool shares at its edges: the --version text, the parse that exits 2
// on a command-line mistake, and the files installed next to the tools (the shipped models).
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

namespace segmatch::cli {

// "segmatch-server 0.1.0 (map schema 3, readable from 1; protocol version 1, revision 4)" and, on a
// second line, the folder of the shipped models it uses ("models: /usr/share/segmatch/models").
std::string version_text(const std::string& tool);

// Adds --version (version_text) to `app`.
void add_version_flag(CLI::App& app, const std::string& tool);

// The output every tool spells the same: -o/--output, with the old --out kept as a hidden
// alias so documented commands keep working. A required output is checked by require_output.
CLI::Option* add_output_option(CLI::App& app, std::string& path, const std::string& description);
// After the parse: 2 and a message when a required output is missing, -1 otherwise.
int require_output(const std::string& tool, const std::string& path);

// The options of a ROS 2 bag given where a sequence folder is (io::BagOptions, in its fields'
// order): --points-topic, --pose-topic, --map-frame, --sensor-frame, in their own help group.
void add_bag_options(CLI::App& app, std::string& points_topic, std::string& pose_topic, std::string& map_frame,
                     std::string& sensor_frame);

// A server as every tool names it: --server HOST:PORT. Throws std::invalid_argument naming the
// text when it is not HOST:PORT with a port in 1..65535.
struct HostPort {
  std::string host;
  uint16_t port = 0;
};
HostPort parse_server(const std::string& host_port);
// After the parse: 2 and a message when a --server given is not HOST:PORT, -1 otherwise.
int check_server(const std::string& tool, const std::string& host_port);

// The shared-secret token from --token-file, read the same way by the server and every client:
// the whole file, trailing whitespace (an editor's newline) not part of it. An empty path gives
// an empty token (none); an unreadable file throws std::runtime_error naming it.
std::string read_token_file(const std::string& path);

// Parses the command line. Returns -1 to go on, else the exit status: 0 after --help or
// --version, 2 after a mistake (CLI11's message printed), the same in every tool.
int parse(CLI::App& app, int argc, char** argv);

// A shipped model (e.g. "default-rf.yml"): under PREFIX/share/segmatch/models when the tool runs
// from PREFIX/bin (an installed or unpacked package), else in the source tree it was built
// from. Empty when neither exists.
std::string shipped_model(const std::string& file_name);

}  // namespace segmatch::cli

// In main(): SEGMATCH_CLI_PARSE(app, argc, argv); returns from main when the parse ends the run.
#define SEGMATCH_CLI_PARSE(app, argc, argv)                                        \
  do {                                                                             \
    const int segmatch_cli_status = ::segmatch::cli::parse((app), (argc), (argv)); \
    if (segmatch_cli_status >= 0) return segmatch_cli_status;                      \
  } while (false)
