// Scale-out as shipped: segmatch-server replicas behind HAProxy running
// deploy/haproxy/haproxy.cfg unchanged, its health check speaking SGMQ to replicas that require
// a token. Sixteen vehicles replay the tiny city through the balancer while one replica is
// killed with SIGKILL with requests in flight and started again.
#include "deploy_test_util.h"

#include <segmatch/core/preprocess/preprocess.h>
#include <segmatch/io/cloud_io.h>

#include <atomic>
#include <map>
#include <mutex>
#include <optional>

using namespace segmatch;
using namespace segmatch::testing;
using namespace segmatch::test;

namespace {

constexpr int kVehicles = 16;
constexpr int kLateVehicles = 4;  // join once the killed replica is back

struct Answer {
  std::optional<api::LocalizeReply> reply;
  std::string error;
};

// What a vehicle sends (docs/protocol.md 5.4): each revisit local cloud voxelized with the map's
// grid.
const std::vector<api::LocalizeRequest>& vehicle_requests() {
  static const std::vector<api::LocalizeRequest> requests = [] {
    std::vector<api::LocalizeRequest> out;
    for (const Query& q : test_world().queries()) {
      api::LocalizeRequest r = q.request;
      r.points = voxel_filter(r.points, test_world().config.localizer.segmentation.voxel);
      r.flags |= api::kFlagVoxelized;
      out.push_back(std::move(r));
    }
    return out;
  }();
  return requests;
}

// One vehicle: its own connection through the balancer, every revisit query once, starting at
// a different place on the route than the others.
void drive(int vehicle, uint16_t port, const std::string& token, std::vector<Answer>* answers,
           std::atomic<int>* retries, std::atomic<int>* done) {
  const std::vector<api::LocalizeRequest>& queries = vehicle_requests();
  api::ClientOptions options;
  options.token = token;
  options.reply_timeout_s = 120;
  std::unique_ptr<api::Client> client;
  for (size_t j = 0; j < queries.size(); ++j) {
    const size_t q = (static_cast<size_t>(vehicle) + j) % queries.size();
    try {
      if (!client) client = std::make_unique<api::Client>("127.0.0.1", port, options);
      (*answers)[q].reply = client->localize(queries[q]);
    } catch (const std::exception& e) {
      (*answers)[q].error = e.what();
      if (client) *retries += client->retries_used();
      client.reset();
    }
    ++*done;
  }
  if (client) *retries += client->retries_used();
}

void expect_same_answer(const api::LocalizeReply& got, const api::LocalizeReply& want, const std::string& where) {
  EXPECT_EQ(got.request_id, want.request_id) << where;
  EXPECT_EQ(got.status, want.status) << where << ": " << got.reason << " / " << want.reason;
  EXPECT_EQ(got.inliers, want.inliers) << where;
  EXPECT_EQ(got.matched_segment_ids, want.matched_segment_ids) << where;
  if (got.status != api::LocalizeStatus::kLocalized || want.status != got.status) return;
  EXPECT_LT(position_error_m(got.T_map_local, want.T_map_local), 1e-3) << where;
  EXPECT_LT(angle_error_deg(got.T_map_local, want.T_map_local), 0.01) << where;
}

}  // namespace

// The shipped health check passes on replicas with a token only when it sends that token: with
// a wrong one HAProxy marks the replica down, and nothing gets through.
TEST(Deploy, HealthCheckSendsTheToken) {
  const std::string haproxy = haproxy_binary();
  if (haproxy.empty()) GTEST_SKIP() << "haproxy is not installed (scripts/install-deps.sh installs it)";
  const std::string dir = deploy_folder("wrong-token");
  const std::string token = write_token(dir + "/token", "right-token");
  Replica replica(dir, "r1");
  ASSERT_FALSE(::testing::Test::HasFatalFailure());
  std::ofstream(dir + "/wrong") << "wrong-token\n";
  Balancer balancer(haproxy, dir, {replica.port, replica.port}, dir + "/wrong");
  ASSERT_TRUE(wait_until(
      [&] {
        const std::string log = read_text(balancer.log);
        return count_of(log, "replica1 is DOWN") > 0 && count_of(log, "replica2 is DOWN") > 0;
      },
      20))
      << read_text(balancer.log);
  EXPECT_NE(read_text(balancer.log).find("Layer7"), std::string::npos) << read_text(balancer.log);
  EXPECT_THROW(api::Client("127.0.0.1", balancer.port, client_options(token)).ping(), api::ClientError);
}

TEST(Deploy, HelloHexIsTheCodecsHelloFrame) {
  const std::string dir = deploy_folder("hello");
  for (const std::string& token : {std::string(), std::string("s3cret token"), std::string(300, 'k')}) {
    const std::string path = token.empty() ? "" : dir + "/token";
    if (!token.empty()) write_token(path, token);
    const CommandResult r = run_command(source_path("deploy/haproxy/hello-hex.sh") + " " + path);
    ASSERT_EQ(r.code, 0) << r.output;
    EXPECT_EQ(r.output, to_hex(api::encode(api::HelloRequest{token})) + "\n");
  }
  std::ofstream(dir + "/blank") << "  \n";
  EXPECT_EQ(run_command(source_path("deploy/haproxy/hello-hex.sh") + " " + dir + "/blank").code, 2);
}

// The unit's ExecStart, with the variables of the example environment file (the map, ports and
// listen address pointed at this test), is a command line segmatch-server accepts.
TEST(Deploy, SystemdUnitCommandLineStartsTheServer) {
  const std::string dir = deploy_folder("systemd");
  const std::string token = write_token(dir + "/token", "unit-token");
  std::map<std::string, std::string> env = read_env_file(source_path("deploy/systemd/segmatch-server.env"));
  ASSERT_TRUE(env.count("SEGMATCH_MAP") && env.count("SEGMATCH_PORT")) << "the example environment file lost its keys";
  const uint16_t port = free_loopback_port();
  env["SEGMATCH_MAP"] = test_world().map_path;
  env["SEGMATCH_LISTEN"] = "127.0.0.1";
  env["SEGMATCH_PORT"] = std::to_string(port);
  env["SEGMATCH_METRICS_PORT"] = std::to_string(free_loopback_port());
  env["SEGMATCH_WORKERS"] = "1";
  env["CREDENTIALS_DIRECTORY"] = dir;
  std::vector<std::string> argv = unit_exec_start(source_path("deploy/systemd/segmatch-server@.service"), env);
  ASSERT_GE(argv.size(), 3u);
  EXPECT_EQ(argv[0], "/usr/bin/segmatch-server");
  argv[0] = std::string(SEGMATCH_BIN_DIR) + "/segmatch-server";
  ChildProcess server(argv, dir + "/out", dir + "/log");
  ASSERT_TRUE(wait_until(
      [&] { return read_text(dir + "/out").find("listening on") != std::string::npos || !server.running(); }, 60));
  ASSERT_NE(read_text(dir + "/out").find("listening on"), std::string::npos) << read_text(dir + "/log");
  api::Client client("127.0.0.1", port, client_options(token));
  EXPECT_EQ(client.ping(7), 7u);
  EXPECT_EQ(read_text(dir + "/log").find("WARN"), std::string::npos) << read_text(dir + "/log");
}

// docs/deploy.md's "try it on one machine" block, run as it is written there, with the test's
// map, token and free ports put in its place.
TEST(Deploy, DocumentedCommandsRun) {
  if (haproxy_binary().empty()) GTEST_SKIP() << "haproxy is not installed (scripts/install-deps.sh installs it)";
  const std::string dir = deploy_folder("documented");
  std::string block = documented_block(source_path("docs/deploy.md"));
  ASSERT_NE(block.find("haproxy -db -f deploy/haproxy/haproxy.cfg"), std::string::npos) << block;
  const std::string token_path = dir + "/token";
  write_token(token_path, "documented-token");
  replace_all(block, "map=out/demo/demo-map.sqlite token=$HOME/segmatch-token",
              "map=" + test_world().map_path + " token=" + token_path);
  replace_all(block, "$PWD/build/bin", SEGMATCH_BIN_DIR);
  for (const char* port : {"7878", "7001", "7002"}) replace_all(block, port, std::to_string(free_loopback_port()));
  std::ofstream(dir + "/two.sh") << "set -e\ntrap 'kill $(jobs -p) 2>/dev/null' EXIT\n" << block;
  const CommandResult r = run_command("cd " + source_path("") + " && bash " + dir + "/two.sh");
  EXPECT_EQ(r.code, 0) << block << "\n" << r.output;
  EXPECT_NE(r.output.find("pong from 127.0.0.1:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("tiny-3"), std::string::npos) << r.output;
}

// segmatch-query as a script runs it: exit 0 for a fix, 3 for an answer that is not LOCALIZED.
TEST(Deploy, QueryLocalizeExitsByStatus) {
  const std::string dir = deploy_folder("query");
  const std::string token = write_token(dir + "/token", "query-token");
  Replica replica(dir, "r1");
  ASSERT_FALSE(::testing::Test::HasFatalFailure());
  const Query& fix = test_world().queries().front();  // localized by the server tests
  io::write_kitti_bin(dir + "/fix.bin", fix.request.points);
  io::write_kitti_bin(dir + "/nothing.bin", PointCloud{Point{1.f, 2.f, 3.f, 0.f}, Point{4.f, 5.f, 6.f, 0.f}});
  const Eigen::Vector3d& s = fix.request.sensor_position_local;
  const std::string query = std::string(SEGMATCH_BIN_DIR) +
                            "/segmatch-query --server 127.0.0.1:" + std::to_string(replica.port) + " --token-file " +
                            dir + "/token localize ";
  const CommandResult found = run_command(query + dir + "/fix.bin --sensor " + std::to_string(s.x()) + "," +
                                          std::to_string(s.y()) + "," + std::to_string(s.z()));
  EXPECT_EQ(found.code, 0) << found.output;
  EXPECT_EQ(found.output.rfind("localized ", 0), 0u) << found.output;
  const CommandResult refused = run_command(query + dir + "/nothing.bin");
  EXPECT_EQ(refused.code, 3) << refused.output;
  EXPECT_NE(refused.output.find("TOO_FEW_SEGMENTS: "), std::string::npos)
      << "the typed reason by default: " << refused.output;
  const CommandResult coded = run_command(query + dir + "/nothing.bin --refusal-code");  // the old spelling
  EXPECT_EQ(coded.code, 3) << coded.output;
  EXPECT_NE(coded.output.find("TOO_FEW_SEGMENTS: "), std::string::npos) << coded.output;
}

// Every vehicle's answers against the single server's (a failure per unanswered or different
// one); returns how many were unanswered and how many localized.
static std::pair<int, int> tally_answers(const std::vector<std::vector<Answer>>& answers,
                                         const std::vector<api::LocalizeReply>& reference) {
  int unanswered = 0, localized = 0;
  for (size_t v = 0; v < answers.size(); ++v)
    for (size_t q = 0; q < reference.size(); ++q) {
      const Answer& a = answers[v][q];
      const std::string where = "vehicle " + std::to_string(v) + " query " + std::to_string(q);
      if (!a.reply) {
        ++unanswered;
        ADD_FAILURE() << where << " was not answered: " << a.error;
        continue;
      }
      localized += a.reply->status == api::LocalizeStatus::kLocalized;
      expect_same_answer(*a.reply, reference[q], where);
    }
  return {unanswered, localized};
}

TEST(Deploy, SixteenVehiclesThroughHaproxySurviveAKilledReplica) {
  const std::string haproxy = haproxy_binary();
  if (haproxy.empty()) GTEST_SKIP() << "haproxy is not installed (scripts/install-deps.sh installs it)";
  const std::vector<api::LocalizeRequest>& queries = vehicle_requests();
  ASSERT_GE(queries.size(), 4u);
  const std::string dir = deploy_folder("kill");
  const std::string token = write_token(dir + "/token", "fleet-token-0123");
  std::vector<std::unique_ptr<Replica>> replicas;
  replicas.push_back(std::make_unique<Replica>(dir, "r1"));
  replicas.push_back(std::make_unique<Replica>(dir, "r2"));
  ASSERT_FALSE(::testing::Test::HasFatalFailure());

  // The answers of a single server, straight to replica 2.
  std::vector<api::LocalizeReply> reference;
  api::Client direct("127.0.0.1", replicas[1]->port, client_options(token));
  for (const api::LocalizeRequest& q : queries) reference.push_back(direct.localize(q));
  direct.close();

  Balancer balancer(haproxy, dir, {replicas[0]->port, replicas[1]->port}, dir + "/token");
  for (auto& r : replicas) ASSERT_TRUE(r->health_checked(2)) << read_text(balancer.log);

  const int total = (kVehicles + kLateVehicles) * static_cast<int>(queries.size());
  std::vector<std::vector<Answer>> answers(kVehicles + kLateVehicles, std::vector<Answer>(queries.size()));
  std::atomic<int> retries{0}, done{0};
  std::vector<std::thread> vehicles;
  for (int v = 0; v < kVehicles; ++v)
    vehicles.emplace_back(drive, v, balancer.port, token, &answers[v], &retries, &done);

  // Replica 1 is killed once a third of the queries are answered, at a moment when it holds a
  // request (its in-flight gauge, read just before), and started again on its port.
  ASSERT_TRUE(wait_until([&] { return done * 3 >= kVehicles * static_cast<int>(queries.size()); }, 300));
  double served_before_kill = 0;
  ASSERT_TRUE(wait_until(
      [&] {
        const std::string metrics = replicas[0]->scrape();
        served_before_kill = localize_count(metrics);
        return metric(metrics, "segmatch_in_flight_requests") >= 1;
      },
      60))
      << "replica 1 never had a request in flight";
  EXPECT_EQ(replicas[0]->process->signal_and_wait(SIGKILL), 128 + SIGKILL);
  const int done_at_kill = done;
  replicas[0]->start();
  ASSERT_FALSE(::testing::Test::HasFatalFailure());
  ASSERT_TRUE(replicas[0]->health_checked(2)) << read_text(balancer.log);

  // New vehicles connect after the restart: the least-connections balance sends them to it.
  for (int v = kVehicles; v < kVehicles + kLateVehicles; ++v)
    vehicles.emplace_back(drive, v, balancer.port, token, &answers[v], &retries, &done);

  // Meanwhile replica 2 is given a new map file (the same segments under a new name) and SIGHUP,
  // as an operator updates a map: it switches while its vehicles' requests go on.
  write_renamed_map(test_world().map_path, replicas[1]->map + ".new", "tiny-3 v2");
  std::filesystem::rename(replicas[1]->map + ".new", replicas[1]->map);
  const int done_at_reload = done;
  ASSERT_EQ(::kill(replicas[1]->process->pid(), SIGHUP), 0);
  const std::string replica2_log = dir + "/r2.log";
  EXPECT_TRUE(
      wait_until([&] { return read_text(replica2_log).find("reloaded: map 'tiny-3 v2'") != std::string::npos; }, 60))
      << read_text(replica2_log);
  for (std::thread& t : vehicles) t.join();
  EXPECT_EQ(api::Client("127.0.0.1", replicas[1]->port, client_options(token)).info().map_name, "tiny-3 v2");
  EXPECT_LT(done_at_reload, total) << "the reload came after the last query";

  const auto [unanswered, localized] = tally_answers(answers, reference);
  const double served_after_restart = localize_count(replicas[0]->scrape());
  const double served_by_2 = localize_count(replicas[1]->scrape()) - static_cast<double>(queries.size());
  std::printf(
      "[deploy] %d queries from %d vehicles through HAProxy, %d localized, %d unanswered, %d sent again "
      "after the SIGKILL (at query %d); replica 1 answered %.0f before it and %.0f after its restart, replica 2 "
      "%.0f (its map reloaded by SIGHUP at query %d)\n",
      total, kVehicles + kLateVehicles, localized, unanswered, retries.load(), done_at_kill, served_before_kill,
      served_after_restart, served_by_2, done_at_reload);
  EXPECT_EQ(unanswered, 0);
  EXPECT_GE(retries, 1) << "no request was lost with the killed replica";
  EXPECT_GT(served_before_kill, 0);
  EXPECT_GT(served_after_restart, 0);
  EXPECT_GT(served_by_2, 0);
}
