// segmatch-query: talks to segmatch-server (ping, info, one localization, or a replayed
// sequence).
#include "query.h"

#include <segmatch/io/cloud_io.h>

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>

using namespace segmatch;

namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

Eigen::Vector3d parse_xyz(const std::string& text) {
  Eigen::Vector3d v;
  char c1 = 0, c2 = 0;
  std::istringstream in(text);
  if (!(in >> v.x() >> c1 >> v.y() >> c2 >> v.z()) || c1 != ',' || c2 != ',' || !v.allFinite())
    throw std::runtime_error("--sensor wants x,y,z, got '" + text + "'");
  return v;
}

void print_info(const api::InfoReply& info) {
  std::printf(
      "map:       %s\nsegments:  %llu\nextent:    (%.1f %.1f %.1f) .. (%.1f %.1f %.1f)\nprotocol:  "
      "%u\nparameters:\n%s\n",
      info.map_name.c_str(), static_cast<unsigned long long>(info.segment_count), info.extent_min.x(),
      info.extent_min.y(), info.extent_min.z(), info.extent_max.x(), info.extent_max.y(), info.extent_max.z(),
      info.protocol_version, info.parameters_json.c_str());
}

// One cloud localized: exit 0 when the answer is LOCALIZED, 3 when it is not (scripts tell a
// fix from a refusal by the status).
int localize_one(api::Client& client, const std::string& cloud_path, const std::string& sensor) {
  api::LocalizeRequest request;
  request.sensor_position_local = parse_xyz(sensor);
  request.points = io::read_cloud(cloud_path).points;
  // Why an answer is refused is what a user asks next: always ask for the typed code. A
  // server older than revision 5 answers MALFORMED ("reserved bits set"); ask it again without.
  request.flags |= api::kFlagRefusalCode;
  auto sent = std::chrono::steady_clock::now();
  api::LocalizeReply reply;
  try {
    reply = client.localize(request);
  } catch (const api::ClientError& e) {
    if (e.kind != api::ClientError::Kind::kServer || e.server_code != api::ErrorCode::kMalformed) throw;
    request.flags &= ~api::kFlagRefusalCode;
    sent = std::chrono::steady_clock::now();
    reply = client.localize(request);
  }
  query::print_reply(reply, ms_since(sent));
  return reply.status == api::LocalizeStatus::kLocalized ? 0 : 3;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"segmatch-query: client of segmatch-server"};
  app.require_subcommand(1);
  std::string host = "127.0.0.1", token_file, cloud_path, sensor = "0,0,0";
  uint16_t port = 7878;
  double timeout_s = 30.0;
  query::ReplayOptions replay;
  std::string server;
  app.add_option("-s,--server", server, "HOST:PORT of segmatch-server (default 127.0.0.1:7878)");
  app.add_option("--host", host, "server address (old spelling; use --server)")->group("");
  app.add_option("--port", port, "server port (old spelling; use --server)")->group("");
  app.add_option("--token-file", token_file, "file holding the server's token");
  app.add_option("--timeout-s", timeout_s, "longest wait for one reply")->capture_default_str();
  CLI::App* ping = app.add_subcommand("ping", "round trip of one PING");
  CLI::App* info = app.add_subcommand("info", "the map the server serves");
  CLI::App* localize = app.add_subcommand("localize", "localize one cloud (.bin/.pcd/.ply, local frame)");
  localize->add_option("cloud", cloud_path, "point cloud file")->required();
  localize->add_option("--sensor", sensor, "sensor position x,y,z in the cloud's frame")->capture_default_str();
  localize
      ->add_flag("--refusal-code",
                 "ask for the reply's typed refusal code (the default since revision 5; a server older than "
                 "revision 5 is asked again without it)")
      ->group("");
  CLI::App* rep = app.add_subcommand("replay", "replay a sequence folder like a vehicle");
  rep->add_option("sequence", replay.folder,
                  "KITTI sequence folder, PCD keyframe folder, or a ROS 2 bag (.mcap, .db3, folder)")
      ->required();
  cli::add_bag_options(*rep, replay.bag.points_topic, replay.bag.pose_topic, replay.bag.map_frame,
                       replay.bag.sensor_frame);
  rep->add_option("--every-m", replay.every_m, "query every this many metres")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  rep->add_option("--first", replay.first, "first scan index");
  rep->add_option("--last", replay.last, "last scan index (inclusive)");
  rep->add_flag("--track", replay.track,
                "track between fixes: each query carries the last fix as its prior (radius growing with the distance "
                "driven since); global at start-up and after repeated failures");
  rep->add_option("--odometry", replay.odometry,
                  "the vehicle's odometry poses file, KITTI or TUM (default: the sequence's odom_poses.txt, else its "
                  "poses.txt, said on the first line)");
  rep->add_option(
         "--newest-m", replay.newest_m,
         "with each cloud also send the scans of the last this many metres, thinned, so that the server answers "
         "the sensor's pose now rather than the odometry-warped cloud's (protocol revision 8; with --segments revision "
         "10; 0: none)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  rep->add_flag("--segments", replay.segments,
                "query by segments (LOCALIZE_SEGMENTS): segment and describe each local cloud here with the map's "
                "parameters and send the segments (a few hundred KB) instead of the cloud (MB)");
  cli::add_version_flag(app, "segmatch-query");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (const int status = cli::check_server("segmatch-query", server); status >= 0) return status;
  if (!server.empty()) {
    const cli::HostPort where = cli::parse_server(server);
    host = where.host, port = where.port;
  }
  try {
    api::ClientOptions options;
    options.token = cli::read_token_file(token_file);
    options.reply_timeout_s = timeout_s;
    api::Client client(host, port, options);
    const auto start = std::chrono::steady_clock::now();
    if (ping->parsed()) {
      client.ping(1);
      std::printf("pong from %s:%u in %.2f ms\n", host.c_str(), port, ms_since(start));
    } else if (info->parsed()) {
      print_info(client.info());
    } else if (localize->parsed()) {
      return localize_one(client, cloud_path, sensor);
    } else {
      return query::replay(client, replay);
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-query: %s\n", e.what());
    return 1;
  }
}
