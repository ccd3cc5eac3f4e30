// The operator's page in a real browser: a server on the tiny city answers a few
// revisit queries and a refusal, then headless Chromium opens the page twice: --dump-dom (the
// DOM after its scripts ran: the statistics, the refusal's reason, the view transform) and
// --screenshot (the segments and the vehicles drawn where the transform puts them, in their
// colours). Skipped when Chromium is not installed (scripts/install-deps.sh installs it).
// SEGMATCH_CONSOLE_SCREENSHOT=FILE keeps the screenshot (docs/img/console.png was taken so).
#include "server/http_util.h"
#include "server_test_util.h"

#include <segmatch/server/console.h>
#include <segmatch/server/metrics.h>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <sstream>

using namespace segmatch;
using namespace segmatch::testing;
using nlohmann::json;

namespace {

const std::string kToken = "page-test-token";

std::string chromium_binary() {
  for (const char* name : {"chromium", "chromium-browser"}) {
    const test::CommandResult r = test::run_command(std::string("command -v ") + name);
    if (r.code == 0 && !r.output.empty()) return r.output.substr(0, r.output.find('\n'));
  }
  return "";
}

// One headless Chromium run on `url`; --virtual-time-budget lets the page load, fetch and poll
// (virtual time stands still while a fetch is pending) before the DOM or the pixels are taken.
// Each run has its own profile. Without --run-all-compositor-stages-before-draw a --screenshot
// run hung 6 times in 10 here (virtual time waiting on a frame that is never drawn; a
// --dump-dom run never did); with it, 0 in 20. A run not finished in 25 s (they take 3-10 s)
// is still killed and tried again, up to three times.
std::string chromium(const std::string& binary, const std::string& what, const std::string& url, const std::string& folder) {
  static int runs = 0;
  test::CommandResult r;
  std::string cmd;
  for (int attempt = 0; attempt < 3; ++attempt) {
    cmd = "timeout -k 5 25 " + binary + " --headless --disable-gpu --no-sandbox --hide-scrollbars --no-first-run "
          "--disable-extensions --force-device-scale-factor=1 --window-size=1200,800 --virtual-time-budget=4000 "
          "--run-all-compositor-stages-before-draw "
          "--user-data-dir=" + folder + "/profile-" + std::to_string(++runs) + " " + what + " '" + url + "'";
    r = test::run_command("(" + cmd + " > " + folder + "/chromium.out 2> " + folder + "/chromium.err)");
    if (r.code == 0) break;
  }
  EXPECT_EQ(r.code, 0) << cmd << "\n" << r.output;
  std::ifstream in(folder + "/chromium.out");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string attribute(const std::string& dom, const std::string& element_id, const std::string& name) {
  const size_t at = dom.find("id=\"" + element_id + "\"");
  if (at == std::string::npos) return "";
  const size_t open = dom.rfind('<', at), close = dom.find('>', at);
  const std::string tag = dom.substr(open, close - open);
  std::smatch m;
  if (!std::regex_search(tag, m, std::regex(name + "=\"([^\"]*)\""))) return "";
  return m[1];
}

std::string element_text(const std::string& dom, const std::string& element_id) {
  const size_t at = dom.find("id=\"" + element_id + "\"");
  if (at == std::string::npos) return "";
  const size_t start = dom.find('>', at) + 1;
  return dom.substr(start, dom.find('<', start) - start);
}

std::string html_escaped(const std::string& text) {
  std::string out;
  for (char c : text) out += c == '&' ? "&amp;" : c == '<' ? "&lt;" : c == '>' ? "&gt;" : std::string(1, c);
  return out;
}

// Pixels within `radius` of (x, y) whose colour passes `is`.
template <typename Pred>
int pixels_near(const cv::Mat& image, double x, double y, int radius, Pred is) {
  int n = 0;
  for (int dy = -radius; dy <= radius; ++dy)
    for (int dx = -radius; dx <= radius; ++dx) {
      const int px = static_cast<int>(std::lround(x)) + dx, py = static_cast<int>(std::lround(y)) + dy;
      if (px < 0 || py < 0 || px >= image.cols || py >= image.rows) continue;
      const cv::Vec3b bgr = image.at<cv::Vec3b>(py, px);
      n += is(bgr[2], bgr[1], bgr[0]);
    }
  return n;
}

// The page's colours (server/console/app.js kColors), with room for antialiasing and fading.
bool segment_blue(int r, int g, int b) { return b > 200 && r < 110 && g > 90 && g < 170; }
bool localized_green(int r, int g, int b) { return g > 170 && r < 90 && b < 160; }
bool refused_red(int r, int g, int b) { return r > 190 && g < 90 && b < 120; }

// What the page should show: one vehicle replayed three revisit queries; another was refused at
// its prior, the bounds' corner farthest from the first.
struct Fleet {
  std::vector<Eigen::Vector3d> localized_at;
  Eigen::Vector3d prior_at;
  api::LocalizeReply refused;
};

Fleet replay(const RunningServer& s, const server::LoadedMap& map) {
  Fleet f;
  api::Client vehicle = s.client(kToken);
  for (size_t i = 0; i < 3; ++i) {
    const Query& q = test_world().queries()[i];
    const api::LocalizeReply r = vehicle.localize(q.request);
    if (r.status == api::LocalizeStatus::kLocalized) f.localized_at.push_back(r.T_map_local * q.request.sensor_position_local);
  }
  if (f.localized_at.empty()) return f;
  f.prior_at = map.extent_min;
  for (const Eigen::Vector3d& corner : {map.extent_min, map.extent_max, Eigen::Vector3d(map.extent_min.x(), map.extent_max.y(), 0),
                                       Eigen::Vector3d(map.extent_max.x(), map.extent_min.y(), 0)})
    if ((corner - f.localized_at.front()).head<2>().norm() > (f.prior_at - f.localized_at.front()).head<2>().norm()) f.prior_at = corner;
  f.prior_at.z() = 0;
  api::LocalizeRequest refuse;
  refuse.request_id = 99;
  refuse.flags = api::kFlagHasPrior;
  refuse.T_map_local_prior.translation() = f.prior_at;
  refuse.prior_radius_m = 5.0;
  refuse.points.push_back(Point{1.f, 1.f, 1.f, 0.f});
  f.refused = s.client(kToken).localize(refuse);
  return f;
}

// The segments blue at (nearly) every centroid and nowhere in the margin; a green disc where
// each localization put the sensor; a red ring at the refusal's prior.
void check_pixels(const cv::Mat& shot, const server::LoadedMap& map, const Fleet& f, const std::function<cv::Point2d(const Eigen::Vector3d&)>& to_px) {
  size_t blue = 0, checked = 0;
  for (const Segment& seg : map.localizer->targets()) {
    const cv::Point2d p = to_px(seg.centroid.cast<double>());
    bool near_vehicle = cv::norm(p - to_px(f.prior_at)) < 22;
    for (const Eigen::Vector3d& v : f.localized_at) near_vehicle |= cv::norm(p - to_px(v)) < 22;
    if (near_vehicle) continue;
    ++checked;
    blue += pixels_near(shot, p.x, p.y, 1, segment_blue) > 0;
  }
  EXPECT_GT(checked, 50u);
  EXPECT_GE(blue, checked * 95 / 100) << blue << " of " << checked << " segment centroids drawn blue";
  EXPECT_EQ(pixels_near(shot, 6, 6, 5, segment_blue), 0);
  for (const Eigen::Vector3d& v : f.localized_at) {
    const cv::Point2d p = to_px(v);
    // The newest is a 7 px disc, the older ones 3 px: either fills most of the 5 x 5 around it.
    EXPECT_GE(pixels_near(shot, p.x, p.y, 2, localized_green), 12) << "no vehicle drawn at " << p;
  }
  const cv::Point2d r = to_px(f.prior_at);
  EXPECT_GE(pixels_near(shot, r.x, r.y, 9, refused_red), 15) << "no refusal drawn at " << r;
  EXPECT_LE(pixels_near(shot, r.x, r.y, 2, refused_red), 4) << "a refusal is a ring, not a disc";
}

}  // namespace

TEST(ServerConsole, PageDrawsTheMapAndTheFleetAndShowsRefusals) {
  const std::string browser = chromium_binary();
  if (browser.empty()) GTEST_SKIP() << "chromium is not installed (scripts/install-deps.sh installs it): the page was not opened";
  auto metrics = std::make_shared<server::Metrics>();
  server::ServerConfig config;
  config.token = kToken;
  config.metrics = metrics;
  RunningServer s(config);
  server::ConsoleConfig cc;
  cc.token = kToken;
  const server::Console page(cc, *s.server);
  const server::LoadedMap& map = *s.server->map();
  const Fleet fleet = replay(s, map);
  ASSERT_FALSE(fleet.localized_at.empty());
  ASSERT_NE(fleet.refused.status, api::LocalizeStatus::kLocalized);
  const json answers = json::parse(http_get(page.port(), "/api/answers?token=" + kToken).body);
  const std::string refusal_code = answers["answers"].back()["refusal"];

  // The statistics agree with the server's counters and with Prometheus'.
  const json stats = json::parse(http_get(page.port(), "/api/stats?token=" + kToken).body);
  const server::ServerCounters counters = s.server->counters();
  EXPECT_EQ(stats["counters"]["localize_requests"], counters.localize_requests);
  EXPECT_EQ(stats["counters"]["localized"], counters.localized);
  EXPECT_EQ(stats["localization"]["by_type_status"]["LOCALIZE/localized"], fleet.localized_at.size());
  const std::string prom = metrics->text();
  EXPECT_NE(prom.find("segmatch_requests_total{status=\"localized\",type=\"LOCALIZE\"} " + std::to_string(fleet.localized_at.size())),
            std::string::npos) << prom;
  EXPECT_EQ(stats["localization"]["latency_ms"]["samples"], counters.localize_requests);

  // The DOM after the page's scripts ran: its numbers, the refusal's reason, the view transform.
  const std::string folder = test_world().folder + "/console";
  std::filesystem::create_directories(folder);
  // One poll, then nothing in flight: a run whose page kept polling hung now and then (no
  // screenshot after minutes) while virtual time waited on the fetches.
  // No fading within the hour: a retried screenshot comes a minute later.
  const std::string url = page.url() + "?token=" + kToken + "&size=860x700&polls=1&fade_s=3600";
  const std::string dom = chromium(browser, "--dump-dom", url, folder);
  ASSERT_FALSE(attribute(dom, "map", "data-scale").empty()) << dom.substr(0, 4000);
  EXPECT_EQ(element_text(dom, "map-name"), "tiny-3");
  EXPECT_EQ(element_text(dom, "stat-localize_requests"), std::to_string(counters.localize_requests));
  EXPECT_EQ(element_text(dom, "stat-localized"), std::to_string(counters.localized));
  EXPECT_EQ(element_text(dom, "stat-errors"), std::to_string(counters.errors));
  EXPECT_NE(dom.find("id=\"refusal-" + refusal_code + "\""), std::string::npos) << "refusals by reason";
  EXPECT_NE(dom.find(html_escaped(refusal_code + ": " + fleet.refused.reason)), std::string::npos) << "the refusal's reason";
  const double scale = std::stod(attribute(dom, "map", "data-scale")), cx = std::stod(attribute(dom, "map", "data-cx")),
               cy = std::stod(attribute(dom, "map", "data-cy"));

  chromium(browser, "--screenshot=" + folder + "/console.png", url, folder);
  const cv::Mat shot = cv::imread(folder + "/console.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty());
  if (const char* keep = std::getenv("SEGMATCH_CONSOLE_SCREENSHOT"))
    std::filesystem::copy_file(folder + "/console.png", keep, std::filesystem::copy_options::overwrite_existing);
  // The canvas is 860 x 700 (?size=) at the page's top left: its centre is (430, 350).
  check_pixels(shot, map, fleet, [&](const Eigen::Vector3d& v) { return cv::Point2d(430 + (v.x() - cx) * scale, 350 - (v.y() - cy) * scale); });
}
