// The JSON bodies of the operator's page API (docs/console.md): built from the server's map,
// counters and recent answers; no HTTP here (console.cpp routes and answers).
#pragma once

#include "segmatch/server/server.h"

#include <cstdint>
#include <optional>
#include <string>

namespace segmatch {
namespace server {

// GET /api/map: name, schema, bounds, parameters, profile, trajectory, the tiles' scheme.
std::string map_json(const LoadedMap& map);
// GET /api/stats: the server's counters and the localization statistics (recent.h).
std::string stats_json(const Server& server, double uptime_s);
// GET /api/answers?since=C&max=N
std::string answers_json(const Recent& recent, uint64_t since, size_t max_answers);

// A query parameter's value ("" when absent); civetweb decodes it.
std::string query_value(const char* query_string, const char* name);
// A non-negative integer written in decimal, within [0, max]; nullopt otherwise.
std::optional<uint64_t> parse_count(const std::string& text, uint64_t max);
// A signed decimal integer within [-max, max]; nullopt otherwise.
std::optional<int64_t> parse_int(const std::string& text, int64_t max);

}  // namespace server
}  // namespace segmatch
