// Shared by segmatch-query's commands.
#pragma once

#include <segmatch/api/client.h>
#include <segmatch/io/sequence.h>

#include <string>

namespace segmatch::query {

struct ReplayOptions {
  std::string folder;      // a sequence folder or a ROS 2 bag
  io::BagOptions bag;      // which topics of a bag
  double every_m = 10.0;   // one query each time the vehicle drove this far
  size_t first = 0;        // first scan index
  size_t last = SIZE_MAX;  // last scan index (inclusive)
  bool track = false;      // api::Tracker: the last fix is the next query's prior
  std::string odometry;    // poses file to accumulate with (default: odom_poses.txt, else poses.txt)
  bool segments = false;   // LOCALIZE_SEGMENTS: segment here, send the segments
  double newest_m = 10.0;  // LOCALIZE: also send the scans of the last this many metres (0: none)
};

// Replays a recorded sequence like a vehicle: accumulates its scans into a local cloud from
// the sequence's own poses (the odometry frame), queries every `every_m` metres, prints each
// answer and a summary. Returns the process exit code.
int replay(api::Client& client, const ReplayOptions& options);

void print_reply(const api::LocalizeReply& reply, double round_trip_ms);

}  // namespace segmatch::query
