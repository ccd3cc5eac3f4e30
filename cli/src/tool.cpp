#include "segmatch/cli/tool.h"

#include <segmatch/api/protocol.h>
#include <segmatch/storage/map_types.h>

#include <unistd.h>

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

namespace segmatch::cli {

std::string version_text(const std::string& tool) {
  const std::string model = shipped_model("default-rf.yml");
  return tool + " " SEGMATCH_VERSION " (map schema " + std::to_string(storage::kSchemaVersion) + ", readable from " +
         std::to_string(storage::kOldestReadableSchemaVersion) + "; protocol version " +
         std::to_string(api::kProtocolVersion) + ", revision " + std::to_string(api::kProtocolRevision) +
         ")\nmodels: " +
         (model.empty() ? std::string("none installed") : std::filesystem::path(model).parent_path().string());
}

void add_version_flag(CLI::App& app, const std::string& tool) { app.set_version_flag("--version", version_text(tool)); }

CLI::Option* add_output_option(CLI::App& app, std::string& path, const std::string& description) {
  CLI::Option* output = app.add_option("-o,--output", path, description);
  app.add_option("--out", path, description)->group("");  // an empty group is hidden from --help
  return output;
}

void add_bag_options(CLI::App& app, std::string& points_topic, std::string& pose_topic, std::string& map_frame,
                     std::string& sensor_frame) {
  const std::string group = "ROS 2 bag input (an .mcap or .db3 file, or a rosbag2 folder)";
  app.add_option("--points-topic", points_topic, "sensor_msgs/msg/PointCloud2 topic (default: the bag's only one)")
      ->group(group);
  app.add_option(
         "--pose-topic", pose_topic,
         "poses from this nav_msgs/msg/Odometry or geometry_msgs/msg/PoseStamped topic (default: the bag's only one, "
         "else /tf)")
      ->group(group);
  app.add_option("--map-frame", map_frame, "poses from /tf and /tf_static: the sensor's pose in this frame")
      ->group(group);
  app.add_option("--sensor-frame", sensor_frame, "with --map-frame: the sensor's frame (default: the clouds' frame_id)")
      ->group(group);
}

int require_output(const std::string& tool, const std::string& path) {
  if (!path.empty()) return -1;
  std::fprintf(stderr, "%s: error: -o/--output is required\n", tool.c_str());
  return 2;
}

HostPort parse_server(const std::string& host_port) {
  const size_t colon = host_port.rfind(':');
  HostPort out;
  if (colon != std::string::npos && colon > 0 && colon + 1 < host_port.size() &&
      host_port.find_first_not_of("0123456789", colon + 1) == std::string::npos && host_port.size() - colon <= 6) {
    const unsigned long port = std::stoul(host_port.substr(colon + 1));
    if (port >= 1 && port <= 65535) {
      out.host = host_port.substr(0, colon);
      out.port = static_cast<uint16_t>(port);
      return out;
    }
  }
  throw std::invalid_argument("--server wants HOST:PORT (port 1-65535), got '" + host_port + "'");
}

int check_server(const std::string& tool, const std::string& host_port) {
  if (host_port.empty()) return -1;
  try {
    parse_server(host_port);
    return -1;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "%s: error: %s\n", tool.c_str(), e.what());
    return 2;
  }
}

std::string read_token_file(const std::string& path) {
  if (path.empty()) return {};
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read token file " + path);
  std::ostringstream text;
  text << in.rdbuf();
  std::string token = text.str();
  while (!token.empty() && std::isspace(static_cast<unsigned char>(token.back()))) token.pop_back();
  return token;
}

int parse(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
    return -1;
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
}

namespace {

// The folder of the running program (/proc/self/exe); empty when unknown.
std::filesystem::path program_folder() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::path() : exe.parent_path();
}

}  // namespace

std::string shipped_model(const std::string& file_name) {
  std::error_code ec;
  const std::filesystem::path folder = program_folder();
  if (!folder.empty()) {
    const std::filesystem::path installed = folder.parent_path() / "share" / "segmatch" / "models" / file_name;
    if (std::filesystem::exists(installed, ec)) return installed.string();
  }
  const std::filesystem::path source = std::filesystem::path(SEGMATCH_SOURCE_MODELS_DIR) / file_name;
  return std::filesystem::exists(source, ec) ? source.string() : std::string();
}

}  // namespace segmatch::cli
