// The operator's page in a real browser: a server answers localizations and a refusal, then
// headless Chromium opens the page with the token in its address (/?token=...), twice. First
// the whole map: its DOM (the statistics, the refusal's reason, the view transform) and its
// pixels (the segments, the first traversal, the vehicles and the refusal where the transform
// puts them, in their colours; the panel styled). Then zoomed on the newest localized answer:
// its covariance ellipse, a ring of the expected size. Skipped when Chromium is not installed
// (scripts/install-deps.sh installs it).
//
// By default on the server suites' tiny city (its map copied with the first traversal as the
// trajectory: the shared map has none), three revisit queries of one vehicle.
// SEGMATCH_CONSOLE_DEMO=FOLDER (scripts/demo.sh's output: demo-map.sqlite and world/): the demo
// city instead, two vehicles replaying its sequence 01 through segmatch-eval (docs/console.md).
// SEGMATCH_CONSOLE_SCREENSHOT=FILE keeps the whole map's screenshot (docs/img/console.png and
// docs/img/console-demo.png are taken so).
#include "server/console_page.h"
#include "server/http_util.h"
#include "server_test_util.h"

#include <segmatch/server/console.h>
#include <segmatch/server/metrics.h>
#include <segmatch/sim/city.h>
#include <segmatch/sim/dataset.h>
#include <segmatch/storage/map_reader.h>
#include <segmatch/storage/map_writer.h>

#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <filesystem>
#include <iomanip>

using namespace segmatch;
using namespace segmatch::testing;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

const std::string kToken = "page-test-token";

// The run's scratch folder: the shared world's (removed with it), or for the demo one of its
// own, so that the demo run does not build the tiny world.
struct Scratch {
  explicit Scratch(bool demo)
      : path(demo ? (fs::temp_directory_path() / ("segmatch_console_demo_" + std::to_string(::getpid()))).string()
                  : test_world().folder + "/console"),
        own(demo) {
    fs::create_directories(path);
  }
  ~Scratch() {
    std::error_code ec;
    if (own && !std::getenv("SEGMATCH_KEEP_TEST_FILES")) fs::remove_all(path, ec);
  }
  const std::string path;
  const bool own;
};

// The shared map with the tiny city's first traversal as its trajectory: make_city is
// deterministic, so this is the traversal the map's segments were taken along.
std::shared_ptr<const server::LoadedMap> tiny_map_with_trajectory(const std::string& folder) {
  const storage::MapReader reader = storage::MapReader::open(test_world().map_path);
  const sim::City city = sim::make_city(sim::dataset_preset("tiny", 3));
  std::vector<storage::Keyframe> keyframes;
  for (size_t i = 0; i < city.first.size(); ++i)
    keyframes.push_back({static_cast<uint32_t>(i), city.first.times_s[i], city.first.T_world_lidar[i]});
  const std::string path = folder + "/tiny-with-trajectory.sqlite";
  storage::MapWriter writer = storage::MapWriter::create(path, reader.metadata(), true);
  writer.add_segments(reader.load_segments(), {});
  writer.set_trajectory(keyframes);
  writer.commit();
  return server::load_map(path);
}

// One vehicle, three revisit queries; where it was localized.
std::vector<Eigen::Vector3d> replay_tiny(const RunningServer& s) {
  std::vector<Eigen::Vector3d> localized_at;
  api::Client vehicle = s.client(kToken);
  for (size_t i = 0; i < 3; ++i) {
    const Query& q = test_world().queries()[i];
    const api::LocalizeReply r = vehicle.localize(q.request);
    if (r.status == api::LocalizeStatus::kLocalized)
      localized_at.push_back(r.T_map_local * q.request.sensor_position_local);
  }
  return localized_at;
}

// The demo city as docs/console.md shows it: its sequence 01 replayed through this server by
// two vehicles (segmatch-eval localize, one connection each), one asking globally every 5 m up
// to scan 400, one tracking every 4 m from scan 400 to 720. The replays end there, not at the
// sequence's end (where both would stand on the same street): where the two were when the
// picture was first taken by hand, 24 s into full replays.
void replay_demo(const RunningServer& s, const std::string& demo, const std::string& folder) {
  const std::string eval = std::string(SEGMATCH_BIN_DIR) + "/segmatch-eval";
  ASSERT_TRUE(fs::exists(eval)) << eval << " is missing: cmake --build build --target segmatch-eval";
  const std::string token_file = folder + "/token";
  std::ofstream(token_file) << kToken;
  ::chmod(token_file.c_str(), 0600);
  const std::string common = "'" + eval + "' localize --map '" + demo + "/demo-map.sqlite' --sim '" + demo +
                             "/world' --server 127.0.0.1:" + std::to_string(s.server->port()) + " --token-file '" +
                             token_file + "' --quiet";
  const test::CommandResult r =
      test::run_command("(" + common + " --every-m 5 --last 400 > '" + folder + "/global.log' 2>&1 & a=$!; " + common +
                        " --every-m 4 --track --first 400 --last 720 > '" + folder +
                        "/tracking.log' 2>&1 & b=$!; "
                        "wait $a; ra=$?; wait $b; rb=$?; exit $((ra | rb)))");
  ASSERT_EQ(r.code, 0) << r.output
                       << test::run_command("tail -5 '" + folder + "/global.log' '" + folder + "/tracking.log'").output;
}

// A refusal at its prior: the corner of the map's bounds farthest from `from`.
std::pair<Eigen::Vector3d, api::LocalizeReply> refuse_far_from(const RunningServer& s, const server::LoadedMap& map,
                                                               const Eigen::Vector3d& from) {
  Eigen::Vector3d prior = map.extent_min;
  for (const Eigen::Vector3d& corner :
       {map.extent_min, map.extent_max, Eigen::Vector3d(map.extent_min.x(), map.extent_max.y(), 0),
        Eigen::Vector3d(map.extent_max.x(), map.extent_min.y(), 0)})
    if ((corner - from).head<2>().norm() > (prior - from).head<2>().norm()) prior = corner;
  prior.z() = 0;
  api::LocalizeRequest refuse;
  refuse.request_id = 99;
  refuse.flags = api::kFlagHasPrior;
  refuse.T_map_local_prior.translation() = prior;
  refuse.prior_radius_m = 5.0;
  refuse.points.push_back(Point{1.f, 1.f, 1.f, 0.f});
  return {prior, s.client(kToken).localize(refuse)};
}

json get_json(uint16_t port, const std::string& target) {
  const HttpReply r = http_get(port, target + (target.find('?') == std::string::npos ? "?" : "&") + "token=" + kToken);
  EXPECT_EQ(r.status, 200) << target << ": " << r.body;
  return json::parse(r.body, nullptr, false);
}

// Every answer the server keeps, oldest first.
json all_answers(uint16_t port) {
  json out = json::array();
  for (uint64_t cursor = 0;;) {
    const json reply = get_json(port, "/api/answers?since=" + std::to_string(cursor));
    if (reply["answers"].empty()) return out;
    for (const json& a : reply["answers"]) out.push_back(a);
    cursor = reply["cursor"];
  }
}

size_t localized_in(const json& answers) {
  return static_cast<size_t>(
      std::count_if(answers.begin(), answers.end(), [](const json& a) { return a["status"] == "localized"; }));
}

// The statistics agree with the server's counters, with Prometheus' and with the answers.
void check_statistics(uint16_t port, const server::Server& server, const server::Metrics& metrics, size_t localized) {
  const json stats = get_json(port, "/api/stats");
  const server::ServerCounters counters = server.counters();
  EXPECT_EQ(stats["counters"]["localize_requests"], counters.localize_requests);
  EXPECT_EQ(stats["counters"]["localized"], counters.localized);
  EXPECT_EQ(counters.localized, localized);
  EXPECT_EQ(stats["localization"]["by_type_status"]["LOCALIZE/localized"], localized);
  const std::string prom = metrics.text();
  EXPECT_NE(prom.find("segmatch_requests_total{status=\"localized\",type=\"LOCALIZE\"} " + std::to_string(localized)),
            std::string::npos)
      << prom;
  EXPECT_EQ(stats["localization"]["latency_ms"]["samples"], std::min<uint64_t>(counters.localize_requests, 1024));
}

// The page zoomed on the newest localized answer that carries a covariance: a box whose fit
// (within 652 px of the canvas) makes the 2-sigma ellipse's semi-major axis 150 px.
void check_zoomed_ellipse(const std::string& browser, const std::string& url, const std::string& folder,
                          const std::vector<DrawnAnswer>& drawn) {
  const auto with_ellipse = std::find_if(drawn.rbegin(), drawn.rend(), [](const DrawnAnswer& a) {
    return a.newest && a.localized() && !a.answer["pose"]["from_prior"].get<bool>() &&
           a.answer.contains("covariance_xy");
  });
  ASSERT_NE(with_ellipse, drawn.rend()) << "no newest answer of a client carries a covariance";
  const json& c = with_ellipse->answer["covariance_xy"];
  const double mean = (c[0].get<double>() + c[2].get<double>()) / 2;
  const double major_sigma =
      std::sqrt(mean + std::hypot((c[0].get<double>() - c[2].get<double>()) / 2, c[1].get<double>()));
  const double half = 652.0 * 2 * major_sigma / 150 / 2;
  std::ostringstream box;
  box << std::setprecision(12) << with_ellipse->x() - half << ',' << with_ellipse->y() - half << ','
      << with_ellipse->x() + half << ',' << with_ellipse->y() + half;
  const PageRun zoomed = open_page(browser, url + "&view=" + box.str(), folder, folder + "/ellipse.png");
  ASSERT_FALSE(zoomed.shot.empty());
  const View near = view_of(zoomed.dom, 860, 700);
  EXPECT_NEAR(near.cx, with_ellipse->x(), 1e-6);
  check_ellipse(zoomed.shot, near, *with_ellipse);
}

}  // namespace

TEST(ServerConsole, PageDrawsTheMapAndTheFleetAndShowsRefusals) {
  const std::string browser = chromium_binary();
  if (browser.empty())
    GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh installs it): the page was not opened";
  const char* demo = std::getenv("SEGMATCH_CONSOLE_DEMO");
  const Scratch folder(demo != nullptr);
  auto metrics = std::make_shared<server::Metrics>();
  server::ServerConfig config;
  config.token = kToken;
  config.metrics = metrics;
  const std::shared_ptr<const server::LoadedMap> loaded =
      demo ? server::load_map(std::string(demo) + "/demo-map.sqlite") : tiny_map_with_trajectory(folder.path);
  const server::LoadedMap& map = *loaded;
  RunningServer s(config, loaded);
  server::ConsoleConfig cc;
  cc.token = kToken;
  const server::Console page(cc, *s.server);
  const std::vector<Eigen::Vector3d> tiny_localized = demo ? std::vector<Eigen::Vector3d>{} : replay_tiny(s);
  if (demo) replay_demo(s, demo, folder.path);
  if (::testing::Test::HasFatalFailure()) return;
  json answers = all_answers(page.port());
  const auto first =
      std::find_if(answers.begin(), answers.end(), [](const json& a) { return a["status"] == "localized"; });
  ASSERT_NE(first, answers.end()) << "nothing was localized";
  const auto [prior_at, refused] =
      refuse_far_from(s, map, {(*first)["pose"]["x"].get<double>(), (*first)["pose"]["y"].get<double>(), 0.0});
  ASSERT_NE(refused.status, api::LocalizeStatus::kLocalized);
  answers = all_answers(page.port());
  const std::string refusal_code = answers.back()["refusal"];
  const size_t localized = localized_in(answers);
  if (!demo) {  // the page is served what the vehicle was told
    ASSERT_EQ(localized, tiny_localized.size());
    size_t i = 0;
    for (const json& a : answers)
      if (a["status"] == "localized") {
        const Eigen::Vector2d served(a["pose"]["x"].get<double>(), a["pose"]["y"].get<double>());
        EXPECT_LT((served - tiny_localized[i++].head<2>()).norm(), 1e-6);
      }
  }

  check_statistics(page.port(), *s.server, *metrics, localized);
  const server::ServerCounters counters = s.server->counters();

  // The whole map. One poll, then nothing in flight: a run whose page kept polling hung now and
  // then while virtual time waited on the fetches. No fading within the hour: a retried run
  // comes a minute later.
  const std::string url = page.url() + "?token=" + kToken + "&size=860x700&polls=1&fade_s=3600";
  const PageRun whole = open_page(browser, url, folder.path, folder.path + "/console.png");
  ASSERT_FALSE(whole.shot.empty());
  if (const char* keep = std::getenv("SEGMATCH_CONSOLE_SCREENSHOT"))
    fs::copy_file(folder.path + "/console.png", keep, fs::copy_options::overwrite_existing);
  const std::string& dom = whole.dom;
  EXPECT_EQ(element_text(dom, "map-name"), map.metadata.name);
  EXPECT_EQ(element_text(dom, "stat-localize_requests"), std::to_string(counters.localize_requests));
  EXPECT_EQ(element_text(dom, "stat-localized"), std::to_string(counters.localized));
  EXPECT_EQ(element_text(dom, "stat-errors"), std::to_string(counters.errors));
  EXPECT_NE(dom.find("id=\"refusal-" + refusal_code + "\""), std::string::npos) << "refusals by reason";
  EXPECT_NE(dom.find(html_escaped(refusal_code + ": " + refused.reason)), std::string::npos) << "the refusal's reason";
  const View view = view_of(dom, 860, 700);
  ASSERT_GT(view.scale, 0);
  EXPECT_GE(pixels_near(whole.shot, 1194, 400, 2, panel_background), 15) << "the style sheet was not applied";
  std::vector<Eigen::Vector3d> centroids;
  for (const Segment& seg : map.localizer->targets()) centroids.push_back(seg.centroid.cast<double>());
  const std::vector<DrawnAnswer> drawn = drawn_answers(answers);
  check_segments(whole.shot, view, centroids, drawn);
  check_localized(whole.shot, view, drawn);
  check_refusal(whole.shot, view, prior_at);
  const json trajectory = get_json(page.port(), "/api/map")["trajectory"];
  ASSERT_GT(trajectory.size(), 10u) << "the map has no trajectory to draw";
  check_trajectory(whole.shot, view, trajectory, centroids, drawn);

  check_zoomed_ellipse(browser, url, folder.path, drawn);
}
