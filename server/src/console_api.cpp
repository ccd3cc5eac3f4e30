#include "console_api.h"

#include "console_tiles.h"

#include <segmatch/io/auto_profile.h>

#include <civetweb.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstring>

namespace segmatch {
namespace server {
namespace {

using nlohmann::json;

// At most this many trajectory points go to the page: a city's first traversal has tens of
// thousands of keyframes, and a line through 4000 of them draws the same at any zoom a page shows.
constexpr size_t kMaxTrajectoryPoints = 4000;

json trajectory_json(const std::vector<Eigen::Vector3d>& trajectory) {
  json out = json::array();
  const size_t stride = (trajectory.size() + kMaxTrajectoryPoints - 1) / kMaxTrajectoryPoints;
  for (size_t i = 0; i < trajectory.size(); i += std::max<size_t>(1, stride))
    out.push_back({std::round(trajectory[i].x() * 100) / 100, std::round(trajectory[i].y() * 100) / 100});
  if (!trajectory.empty() && stride > 1)  // the line ends where the traversal ended
    out.push_back({trajectory.back().x(), trajectory.back().y()});
  return out;
}

json answer_json(const Answer& a) {
  json j = {{"cursor", a.cursor},
            {"time", a.unix_time_s},
            {"peer", a.peer},
            {"type", a.type},
            {"request_id", a.request_id},
            {"status", a.status},
            {"refusal", a.refusal},
            {"refusal_code", a.refusal_code},
            {"reason", a.reason},
            {"method", a.method},
            {"latency_ms", std::round(a.latency_ms * 10) / 10}};
  if (a.status == "error") j["error_code"] = a.error_code;
  if (a.has_pose) j["pose"] = {{"x", a.x_m}, {"y", a.y_m}, {"yaw", a.yaw_rad}, {"from_prior", a.pose_from_prior}};
  if (a.has_covariance) j["covariance_xy"] = {a.cov_xx_m2, a.cov_xy_m2, a.cov_yy_m2};
  return j;
}

}  // namespace

std::string map_json(const LoadedMap& map) {
  json j;
  j["name"] = map.metadata.name;
  j["frame"] = map.metadata.frame;
  j["created_utc"] = map.metadata.created_utc;
  j["tool_version"] = map.metadata.tool_version;
  j["schema"] = map.schema_version;
  j["segments"] = map.segment_count();
  j["bounds"] = {{"min", {map.extent_min.x(), map.extent_min.y(), map.extent_min.z()}},
                 {"max", {map.extent_max.x(), map.extent_max.y(), map.extent_max.z()}}};
  j["matcher"] = map.config.localizer.matcher.type == MatcherType::kL2 ? "l2" : "random_forest";
  j["fell_back_to_l2"] = map.fell_back_to_l2;
  j["preset"] = map.config.preset;
  j["surface_layer"] = map.surfaces != nullptr;
  j["parameters"] = json::parse(io::to_json(map.config), nullptr, false);
  j["profile"] = io::describe_profile(map.config);
  j["warnings"] = map.warnings;
  j["trajectory"] = trajectory_json(map.trajectory);
  j["trajectory_keyframes"] = map.trajectory.size();
  j["tiles"] = {{"root_m", kTileRootM}, {"max_level", kTileMaxLevel}, {"max_segments", kTileMaxSegments}};
  return j.dump();
}

std::string stats_json(const Server& server, double uptime_s) {
  const ServerCounters c = server.counters();
  const RecentStats r = server.recent().stats();
  json errors = json::object();
  for (const auto& [code, n] : r.errors) errors[std::to_string(code)] = n;
  json j;
  j["uptime_s"] = uptime_s;
  j["counters"] = {{"frames_received", c.frames_received},
                   {"requests", c.requests},
                   {"localize_requests", c.localize_requests},
                   {"localized", c.localized},
                   {"errors", c.errors},
                   {"timed_out", c.timed_out},
                   {"connections", c.connections},
                   {"refused_connections", c.refused_connections}};
  j["localization"] = {
      {"answered", r.answered},
      {"by_type_status", r.by_type_status},
      {"refusals", r.refusals},
      {"errors", errors},
      {"rate_per_s", r.rate_per_s},
      {"rate_window_s", r.rate_window_s},
      {"latency_ms", {{"p50", r.p50_ms}, {"p90", r.p90_ms}, {"p99", r.p99_ms}, {"samples", r.latency_samples}}}};
  return j.dump();
}

std::string answers_json(const Recent& recent, uint64_t since, size_t max_answers) {
  uint64_t next = 0, missed = 0;
  const std::vector<Answer> answers = recent.since(since, max_answers, next, missed);
  json list = json::array();
  for (const Answer& a : answers) list.push_back(answer_json(a));
  const double now = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  return json{{"cursor", next}, {"missed", missed}, {"capacity", recent.capacity()}, {"now", now}, {"answers", list}}
      .dump();
}

std::string query_value(const char* query_string, const char* name) {
  if (!query_string) return "";
  char buf[1024];  // a longer value (a token of over 1 KiB) reads as absent
  const int n = mg_get_var(query_string, std::strlen(query_string), name, buf, sizeof(buf));
  return n > 0 ? std::string(buf, static_cast<size_t>(n)) : "";
}

std::optional<uint64_t> parse_count(const std::string& text, uint64_t max) {
  if (text.empty() || text.size() > 19) return std::nullopt;
  uint64_t v = 0;
  for (char ch : text) {
    if (ch < '0' || ch > '9') return std::nullopt;
    v = v * 10 + static_cast<uint64_t>(ch - '0');
  }
  if (v > max) return std::nullopt;
  return v;
}

std::optional<int64_t> parse_int(const std::string& text, int64_t max) {
  const bool negative = !text.empty() && text[0] == '-';
  const std::optional<uint64_t> v = parse_count(negative ? text.substr(1) : text, static_cast<uint64_t>(max));
  if (!v) return std::nullopt;
  return negative ? -static_cast<int64_t>(*v) : static_cast<int64_t>(*v);
}

}  // namespace server
}  // namespace segmatch
