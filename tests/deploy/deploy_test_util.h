// The pieces of a deployment on loopback for tests/deploy: segmatch-server replicas as their own
// processes (with a token and a metrics port) and HAProxy running deploy/haproxy/haproxy.cfg as
// shipped, configured through its environment variables.
#pragma once

#include "server/server_test_util.h"
#include "support/process.h"
#include "support/run_command.h"

#include <segmatch/storage/map_reader.h>

#include <sys/stat.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>

namespace segmatch::testing {

inline std::string source_path(const std::string& relative) {
  return std::string(SEGMATCH_SOURCE_DIR) + "/" + relative;
}

// HAProxy from PATH or /usr/sbin (Debian installs it there, outside a user's PATH); empty when
// it is not installed.
inline std::string haproxy_binary() {
  for (const char* candidate : {"/usr/sbin/haproxy", "/usr/local/sbin/haproxy"})
    if (std::filesystem::exists(candidate)) return candidate;
  const test::CommandResult r = test::run_command("command -v haproxy");
  return r.code == 0 ? r.output.substr(0, r.output.find('\n')) : std::string();
}

inline std::string deploy_folder(const std::string& name) {
  const std::string dir = test_world().folder + "/deploy-" + name;
  std::filesystem::create_directories(dir);
  return dir;
}

// A token file as an operator writes it (a trailing newline, mode 600); returns the token.
inline std::string write_token(const std::string& path, const std::string& token) {
  std::ofstream(path) << token << "\n";
  ::chmod(path.c_str(), 0600);
  return token;
}

inline api::ClientOptions client_options(const std::string& token) {
  api::ClientOptions o;
  o.token = token;
  o.reply_timeout_s = 120;
  return o;
}

inline std::string to_hex(const std::vector<uint8_t>& bytes) {
  std::string out;
  char digits[3];
  for (uint8_t b : bytes) {
    std::snprintf(digits, sizeof digits, "%02x", b);
    out += digits;
  }
  return out;
}

inline size_t count_of(const std::string& text, const std::string& what) {
  size_t n = 0;
  for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

// The sum of every sample of a Prometheus metric whose name and labels match `pattern` (a
// regular expression for the part before the value).
inline double metric(const std::string& text, const std::string& pattern) {
  const std::regex line("^" + pattern + "(\\{[^}]*\\})? ([-+0-9.eE]+)$");
  double sum = 0;
  std::istringstream in(text);
  std::smatch m;
  for (std::string l; std::getline(in, l);)
    if (std::regex_match(l, m, line)) sum += std::stod(m[2]);
  return sum;
}

// LOCALIZE requests answered, whatever their status.
inline double localize_count(const std::string& metrics) {
  return metric(metrics, R"(segmatch_requests_total\{status="[a-z_]+",type="LOCALIZE"\})");
}

// The segments of `from` written again as a map named `name` (a new map version, same answers).
inline void write_renamed_map(const std::string& from, const std::string& path, const std::string& name) {
  storage::MapMetadata meta;
  meta.name = name;
  meta.tool_version = "test_deploy";
  meta.parameters_json = io::to_json(test_world().config);
  storage::MapWriter writer = storage::MapWriter::create(path, meta, true);
  writer.add_segments(storage::MapReader::open(from).load_segments(), {});
  writer.commit();
}

// The fenced block between "<!-- deploy-test: begin -->" and "<!-- deploy-test: end -->".
inline std::string documented_block(const std::string& markdown_path) {
  const std::string text = test::read_text(markdown_path);
  const size_t begin = text.find("<!-- deploy-test: begin -->"), end = text.find("<!-- deploy-test: end -->");
  if (begin == std::string::npos || end == std::string::npos) return "";
  const size_t first = text.find('\n', text.find("```", begin)) + 1;
  return text.substr(first, text.rfind("```", end) - first);
}

inline void replace_all(std::string& text, const std::string& from, const std::string& to) {
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
}

// KEY=VALUE lines of a systemd environment file (comments and blank lines skipped).
inline std::map<std::string, std::string> read_env_file(const std::string& path) {
  std::map<std::string, std::string> env;
  std::istringstream in(test::read_text(path));
  for (std::string line; std::getline(in, line);) {
    const size_t eq = line.find('=');
    if (line.empty() || line[0] == '#' || eq == std::string::npos) continue;
    env[line.substr(0, eq)] = line.substr(eq + 1);
  }
  return env;
}

// The unit's ExecStart= (with its continuation lines) split into words, ${VAR} replaced from
// `env` as systemd does; a variable missing from `env` fails the test.
inline std::vector<std::string> unit_exec_start(const std::string& unit_path,
                                                const std::map<std::string, std::string>& env) {
  std::istringstream in(test::read_text(unit_path));
  std::string command;
  bool inside = false;
  for (std::string line; std::getline(in, line);) {
    if (!inside && line.rfind("ExecStart=", 0) != 0) continue;
    if (!inside) line = line.substr(std::string("ExecStart=").size());
    inside = !line.empty() && line.back() == '\\';
    command += (inside ? line.substr(0, line.size() - 1) : line) + " ";
    if (!inside) break;
  }
  const std::regex variable(R"(\$\{([A-Z_]+)\})");
  std::string expanded;
  std::sregex_iterator it(command.begin(), command.end(), variable), end;
  size_t at = 0;
  for (; it != end; ++it) {
    const std::string name = (*it)[1];
    EXPECT_TRUE(env.count(name)) << "the unit uses ${" << name << "}, which the environment file does not set";
    expanded += command.substr(at, static_cast<size_t>(it->position()) - at) + (env.count(name) ? env.at(name) : "");
    at = static_cast<size_t>(it->position() + it->length());
  }
  expanded += command.substr(at);
  std::vector<std::string> words;
  std::istringstream split(expanded);
  for (std::string w; split >> w;) words.push_back(w);
  return words;
}

// segmatch-server on a fixed loopback port (HAProxy's configuration names it), one worker,
// requiring the token of DIR/token, with its metrics endpoint. start() again after a kill
// reuses the port.
struct Replica {
  // Serves its own copy of the world's map, DIR/NAME.sqlite (a reload renames a new map over it).
  Replica(const std::string& dir, const std::string& name)
      : dir(dir),
        name(name),
        map(dir + "/" + name + ".sqlite"),
        port(test::free_loopback_port()),
        metrics_port(test::free_loopback_port()) {
    std::filesystem::copy_file(test_world().map_path, map, std::filesystem::copy_options::overwrite_existing);
    start();
  }
  void start() {
    const std::string binary = std::string(SEGMATCH_BIN_DIR) + "/segmatch-server";
    ASSERT_TRUE(std::filesystem::exists(binary)) << binary << " is not built";
    process = std::make_unique<test::ChildProcess>(
        std::vector<std::string>{binary, "--map", map, "--listen", "127.0.0.1", "--port", std::to_string(port),
                                 "--workers", "1", "--token-file", dir + "/token", "--metrics-port",
                                 std::to_string(metrics_port), "--stats-interval-s", "0", "--log-requests", "off"},
        dir + "/" + name + ".out", dir + "/" + name + ".log");
    ASSERT_TRUE(test::wait_until(
        [&] { return read_out().find("listening on") != std::string::npos || !process->running(); }, 120));
    ASSERT_NE(read_out().find("listening on"), std::string::npos) << test::read_text(dir + "/" + name + ".log");
  }
  std::string read_out() const { return test::read_text(dir + "/" + name + ".out"); }
  std::string scrape() const {
    return test::run_command("curl -s --max-time 5 http://127.0.0.1:" + std::to_string(metrics_port) + "/metrics")
        .output;
  }
  // True once the balancer's health check has passed `checks` times on this process (each check
  // ends with a PING answered ok).
  bool health_checked(int checks) const {
    return test::wait_until(
        [&] { return metric(scrape(), R"(segmatch_requests_total\{status="ok",type="PING"\})") >= checks; }, 30);
  }

  std::string dir, name, map;
  uint16_t port, metrics_port;
  std::unique_ptr<test::ChildProcess> process;
};

// HAProxy in the foreground with deploy/haproxy/haproxy.cfg; its log (state changes, one line per
// connection) goes to `log`.
struct Balancer {
  Balancer(const std::string& haproxy, const std::string& dir, std::vector<uint16_t> replicas,
           const std::string& token_file)
      : port(test::free_loopback_port()), log(dir + "/haproxy.log") {
    const test::CommandResult hello = test::run_command(source_path("deploy/haproxy/hello-hex.sh") + " " + token_file);
    EXPECT_EQ(hello.code, 0) << hello.output;
    process = std::make_unique<test::ChildProcess>(
        std::vector<std::string>{haproxy, "-db", "-f", source_path("deploy/haproxy/haproxy.cfg")}, dir + "/haproxy.out",
        log,
        std::vector<std::string>{"SEGMATCH_LB_BIND=127.0.0.1:" + std::to_string(port),
                                 "SEGMATCH_REPLICA1=127.0.0.1:" + std::to_string(replicas.at(0)),
                                 "SEGMATCH_REPLICA2=127.0.0.1:" + std::to_string(replicas.at(1)),
                                 "SEGMATCH_HELLO_HEX=" + hello.output.substr(0, hello.output.find('\n'))});
    // Listening once a plain TCP connection is accepted.
    EXPECT_TRUE(test::wait_until(
        [&] {
          return test::run_command("bash -c 'exec 3<>/dev/tcp/127.0.0.1/" + std::to_string(port) + "'").code == 0;
        },
        20))
        << test::read_text(log);
  }
  uint16_t port;
  std::string log;
  std::unique_ptr<test::ChildProcess> process;
};

}  // namespace segmatch::testing
