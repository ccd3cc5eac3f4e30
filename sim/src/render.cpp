#include "segmatch/sim/render.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

namespace segmatch::sim {
namespace {

// BGR colours.
const cv::Scalar kRoad(95, 95, 95), kSidewalk(190, 190, 190), kTerrain(170, 205, 175);
const cv::Scalar kBuilding(110, 140, 170), kTree(60, 140, 40), kBush(100, 190, 90);
const cv::Scalar kCar(150, 100, 150), kFirst(220, 80, 20), kSecond(0, 140, 255);

struct Canvas {
  cv::Mat img;
  Eigen::AlignedBox2d bounds;
  double px_per_m = 1.0;
  cv::Point to_px(double x, double y) const {
    return {static_cast<int>(std::lround((x - bounds.min().x()) * px_per_m)),
            static_cast<int>(std::lround((bounds.max().y() - y) * px_per_m))};
  }
  int px(double metres) const { return std::max(1, static_cast<int>(std::lround(metres * px_per_m))); }
};

void fill_rect(Canvas& c, const Eigen::Vector2f& centre, const Eigen::Vector2f& half, float yaw, const cv::Scalar& fill,
               const cv::Scalar* outline) {
  const Eigen::Vector2f ax(std::cos(yaw), std::sin(yaw)), ay(-std::sin(yaw), std::cos(yaw));
  std::vector<cv::Point> pts;
  for (auto [sx, sy] : {std::pair{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}) {
    const Eigen::Vector2f p = centre + sx * half.x() * ax + sy * half.y() * ay;
    pts.push_back(c.to_px(p.x(), p.y()));
  }
  cv::fillConvexPoly(c.img, pts, fill, cv::LINE_AA);
  if (outline) cv::polylines(c.img, pts, true, *outline, 1, cv::LINE_AA);
}

void draw_ground(Canvas& c, const World& w) {
  c.img.setTo(kTerrain);
  const auto& g = w.grid;
  const auto& b = w.bounds;
  const double sw = w.config.sidewalk_width_m;
  // Sidewalk bands first, then roads over them.
  for (size_t i = 0; i < g.x.size(); ++i)
    cv::rectangle(c.img, c.to_px(g.x[i] - 0.5 * g.x_width[i] - sw, b.max().y()),
                  c.to_px(g.x[i] + 0.5 * g.x_width[i] + sw, b.min().y()), kSidewalk, cv::FILLED);
  for (size_t j = 0; j < g.y.size(); ++j)
    cv::rectangle(c.img, c.to_px(b.min().x(), g.y[j] + 0.5 * g.y_width[j] + sw),
                  c.to_px(b.max().x(), g.y[j] - 0.5 * g.y_width[j] - sw), kSidewalk, cv::FILLED);
  for (size_t i = 0; i < g.x.size(); ++i)
    cv::rectangle(c.img, c.to_px(g.x[i] - 0.5 * g.x_width[i], b.max().y()),
                  c.to_px(g.x[i] + 0.5 * g.x_width[i], b.min().y()), kRoad, cv::FILLED);
  for (size_t j = 0; j < g.y.size(); ++j)
    cv::rectangle(c.img, c.to_px(b.min().x(), g.y[j] + 0.5 * g.y_width[j]),
                  c.to_px(b.max().x(), g.y[j] - 0.5 * g.y_width[j]), kRoad, cv::FILLED);
}

void draw_object(Canvas& c, const WorldObject& o, bool highlight) {
  static const cv::Scalar kDark(40, 40, 40), kNew(0, 165, 255);
  const cv::Point p = c.to_px(o.position.x(), o.position.y());
  switch (o.kind) {
    case ObjectKind::kBuilding:
      for (const auto& part : o.parts)
        if (part.shape == Shape::kBox && part.b.z() > 2.0f)  // masses, not facade trim
          fill_rect(c, part.a.head<2>(), part.b.head<2>(), part.yaw, kBuilding, &kDark);
      break;
    case ObjectKind::kTree:
      cv::circle(c.img, p, c.px(o.half_extents.x()), kTree, cv::FILLED, cv::LINE_AA);
      cv::circle(c.img, p, c.px(o.half_extents.x()), cv::Scalar(30, 90, 20), 1, cv::LINE_AA);
      break;
    case ObjectKind::kBush: cv::circle(c.img, p, c.px(0.9), kBush, cv::FILLED, cv::LINE_AA); break;
    case ObjectKind::kHedge: fill_rect(c, o.position, o.half_extents, o.yaw, kBush, nullptr); break;
    case ObjectKind::kWall:
    case ObjectKind::kFence:
      fill_rect(c, o.position, o.half_extents + Eigen::Vector2f(0, 0.1f), o.yaw, kDark, nullptr);
      break;
    case ObjectKind::kCar: fill_rect(c, o.position, o.half_extents, o.yaw, highlight ? kNew : kCar, &kDark); break;
    case ObjectKind::kPedestrian: cv::circle(c.img, p, c.px(0.6), cv::Scalar(200, 0, 200), cv::FILLED); break;
    case ObjectKind::kStreetLamp: cv::circle(c.img, p, c.px(0.6), cv::Scalar(0, 215, 255), cv::FILLED); break;
    case ObjectKind::kPole: cv::circle(c.img, p, c.px(0.4), kDark, cv::FILLED); break;
    case ObjectKind::kSign: cv::circle(c.img, p, c.px(0.5), cv::Scalar(0, 0, 220), cv::FILLED); break;
    case ObjectKind::kBench: fill_rect(c, o.position, o.half_extents, o.yaw, cv::Scalar(40, 80, 140), nullptr); break;
  }
}

void draw_traversal(Canvas& c, const Traversal& t, const cv::Scalar& colour, int thickness, const char* name) {
  std::vector<cv::Point> pts;
  for (const auto& T : t.T_world_lidar) pts.push_back(c.to_px(T.translation().x(), T.translation().y()));
  cv::polylines(c.img, pts, false, colour, thickness, cv::LINE_AA);
  // Direction arrows every 60 m.
  double next = 30.0;
  for (size_t i = 1; i < t.size(); ++i) {
    if (t.odometer_m[i] < next) continue;
    next += 60.0;
    const Eigen::Vector3d p = t.T_world_lidar[i].translation(), d = t.T_world_lidar[i].linear().col(0);
    cv::arrowedLine(c.img, c.to_px(p.x() - 4 * d.x(), p.y() - 4 * d.y()), c.to_px(p.x() + 4 * d.x(), p.y() + 4 * d.y()),
                    colour, thickness, cv::LINE_AA, 0, 0.6);
  }
  cv::circle(c.img, pts.front(), 7, colour, cv::FILLED, cv::LINE_AA);
  cv::putText(c.img, name, pts.front() + cv::Point(9, -9), cv::FONT_HERSHEY_SIMPLEX, 0.7, colour, 2, cv::LINE_AA);
}

void draw_legend(Canvas& c, bool second) {
  struct Item {
    const char* text;
    cv::Scalar colour;
  };
  std::vector<Item> items = {
      {"traversal 00 (map)", kFirst},           {"building", kBuilding},        {"tree", kTree}, {"parked car", kCar},
      {"street lamp", cv::Scalar(0, 215, 255)}, {"sign", cv::Scalar(0, 0, 220)}};
  if (second) {
    items.insert(items.begin() + 1, {"traversal 01 (revisit)", kSecond});
    items.push_back({"car new in 01", cv::Scalar(0, 165, 255)});
    items.push_back({"pedestrian (01)", cv::Scalar(200, 0, 200)});
  }
  const int x0 = 10, y0 = 10, h = 22;
  cv::rectangle(c.img, {x0, y0}, {x0 + 240, y0 + 12 + h * static_cast<int>(items.size())}, cv::Scalar(255, 255, 255),
                cv::FILLED);
  for (size_t k = 0; k < items.size(); ++k) {
    const int y = y0 + 8 + h * static_cast<int>(k);
    cv::rectangle(c.img, {x0 + 8, y}, {x0 + 24, y + 14}, items[k].colour, cv::FILLED);
    cv::putText(c.img, items[k].text, {x0 + 32, y + 13}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1,
                cv::LINE_AA);
  }
  // Scale bar: 100 m.
  const int len = c.px(100.0), yb = c.img.rows - 20;
  cv::rectangle(c.img, {10, yb - 22}, {len + 70, yb + 8}, cv::Scalar(255, 255, 255), cv::FILLED);
  cv::line(c.img, {20, yb}, {20 + len, yb}, cv::Scalar(0, 0, 0), 3);
  cv::putText(c.img, "100 m", {25 + len, yb + 5}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
}

void write_png(const std::string& path, const cv::Mat& img) {
  bool ok = false;
  try {
    ok = cv::imwrite(path, img);
  } catch (const cv::Exception& e) {
    throw std::runtime_error("cannot write image " + path + ": " + e.what());
  }
  if (!ok) throw std::runtime_error("cannot write image " + path);
}

cv::Scalar class_colour(uint16_t cls) {
  switch (cls) {  // SemanticKITTI palette (BGR)
    case semantic::kCar: return {245, 150, 100};
    case semantic::kPerson: return {30, 30, 255};
    case semantic::kRoad: return {255, 0, 255};
    case semantic::kSidewalk: return {75, 0, 75};
    case semantic::kBuilding: return {0, 200, 255};
    case semantic::kFence: return {50, 120, 255};
    case semantic::kOtherStructure: return {0, 150, 255};
    case semantic::kVegetation: return {0, 175, 0};
    case semantic::kTrunk: return {0, 60, 135};
    case semantic::kTerrain: return {80, 240, 150};
    case semantic::kPole: return {150, 240, 255};
    case semantic::kTrafficSign: return {0, 0, 255};
    default: return {255, 255, 255};
  }
}

}  // namespace

void write_world_png(const std::string& path, const World& world, const World* changed, const Traversal& first,
                     const Traversal* second) {
  Canvas c;
  c.bounds = world.bounds;
  c.px_per_m = std::min(4.0, 2400.0 / world.bounds.sizes().maxCoeff());
  c.img = cv::Mat(c.px(world.bounds.sizes().y()), c.px(world.bounds.sizes().x()), CV_8UC3);
  draw_ground(c, world);
  for (const auto& o : world.objects) draw_object(c, o, false);
  if (changed) {
    std::set<uint16_t> before;
    for (const auto& o : world.objects) before.insert(o.instance);
    for (const auto& o : changed->objects)
      if ((o.kind == ObjectKind::kCar || o.kind == ObjectKind::kPedestrian) && !before.count(o.instance))
        draw_object(c, o, true);
  }
  draw_traversal(c, first, kFirst, 3, "00");
  if (second) draw_traversal(c, *second, kSecond, 2, "01");
  draw_legend(c, second != nullptr);
  write_png(path, c.img);
}

namespace {

// Range image of a spinning scan: one row per beam, the highest on top; column j looks at
// azimuth 2*pi*j/columns, drawn with forward (azimuth 0) in the middle and the left side
// (+y) to the left of it. Pixels: 255 near .. 1 at 80 m, 0 for no return.
cv::Mat spinning_range_image(const SimulatedScan& scan, const LidarModel& model) {
  const int beams = static_cast<int>(model.elevations_deg.size());
  cv::Mat range(beams, model.columns, CV_8UC1, cv::Scalar(0));
  // Row 0 is the highest beam, whatever order the model lists them in.
  std::vector<int> row_of_beam(beams);
  for (int b = 0; b < beams; ++b)
    row_of_beam[b] = static_cast<int>(std::count_if(model.elevations_deg.begin(), model.elevations_deg.end(),
                                                    [&](float e) { return e > model.elevations_deg[b]; }));
  for (const auto& p : scan.points) {
    const double r = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    const double az = std::atan2(p.y, p.x), el = std::asin(p.z / std::max(r, 1e-6)) * 180.0 / M_PI;
    const long j = std::lround(az / (2 * M_PI) * model.columns);
    const int col = static_cast<int>(((model.columns / 2 - j) % model.columns + model.columns) % model.columns);
    int beam = 0;
    for (int b = 1; b < beams; ++b)
      if (std::abs(model.elevations_deg[b] - el) < std::abs(model.elevations_deg[beam] - el)) beam = b;
    range.at<uint8_t>(row_of_beam[beam], col) = static_cast<uint8_t>(std::clamp(255.0 - r * 255.0 / 80.0, 1.0, 255.0));
  }
  return range;
}

// Front view of a rosette scan: 0.25 deg cells of azimuth and elevation over its field of
// view, as seen from behind the sensor (left, +y, to the left). 255 near .. 1 at 40 m (a
// short-range sensor), 0 for no return.
cv::Mat rosette_range_image(const SimulatedScan& scan, const LidarModel& model) {
  constexpr double kCellDeg = 0.25;
  const double half_h = 0.5 * model.rosette.fov_horizontal_deg, half_v = 0.5 * model.rosette.fov_vertical_deg;
  const int cols = static_cast<int>(std::ceil(2 * half_h / kCellDeg)),
            rows = static_cast<int>(std::ceil(2 * half_v / kCellDeg));
  cv::Mat range(rows, cols, CV_8UC1, cv::Scalar(0));
  for (const auto& p : scan.points) {
    const double r = std::sqrt(p.x * p.x + p.y * p.y + p.z * p.z);
    const double az = std::atan2(p.y, p.x) * 180.0 / M_PI;
    const double el = std::atan2(p.z, std::hypot(p.x, p.y)) * 180.0 / M_PI;
    const int col = static_cast<int>(std::floor((half_h - az) / kCellDeg));
    const int row = static_cast<int>(std::floor((half_v - el) / kCellDeg));
    if (col < 0 || row < 0 || col >= cols || row >= rows) continue;
    range.at<uint8_t>(row, col) = static_cast<uint8_t>(std::clamp(255.0 - r * 255.0 / 40.0, 1.0, 255.0));
  }
  return range;
}

}  // namespace

void write_scan_png(const std::string& path, const SimulatedScan& scan, const LidarModel& model,
                    const std::string& title) {
  const bool rosette = model.pattern == ScanPattern::kRosette;
  const cv::Mat range = rosette ? rosette_range_image(scan, model) : spinning_range_image(scan, model);
  const int beams = range.rows;
  const int width = 1600, row_h = std::max(2, 256 / beams), range_h = rosette ? 400 : beams * row_h;
  // A rosette's front view keeps its aspect ratio, centred in the strip.
  const int range_w = rosette ? static_cast<int>(std::lround(double(range_h) * range.cols / range.rows)) : width;
  const int bev = 800, title_h = 30;
  cv::Mat img(title_h + range_h + bev, width, CV_8UC3, cv::Scalar(25, 25, 25));
  cv::Mat range_big, range_colour;
  cv::resize(range, range_big, cv::Size(range_w, range_h), 0, 0, cv::INTER_NEAREST);
  cv::applyColorMap(range_big, range_colour, cv::COLORMAP_TURBO);
  range_colour.setTo(cv::Scalar(25, 25, 25), range_big == 0);
  range_colour.copyTo(img(cv::Rect((width - range_w) / 2, title_h, range_w, range_h)));
  // Bird's-eye view, 100 m x 100 m around the sensor, by semantic class.
  cv::Mat top = img(cv::Rect(0, title_h + range_h, bev, bev));
  const double scale = bev / 100.0;
  for (size_t i = 0; i < scan.points.size(); ++i) {
    const auto& p = scan.points[i];
    const cv::Point q(static_cast<int>(bev / 2 - p.y * scale), static_cast<int>(bev / 2 - p.x * scale));
    if (q.x >= 0 && q.y >= 0 && q.x < bev && q.y < bev) {
      const cv::Scalar c = class_colour(label_class(scan.labels[i]));
      top.at<cv::Vec3b>(q) = cv::Vec3b(uchar(c[0]), uchar(c[1]), uchar(c[2]));
    }
  }
  cv::circle(top, {bev / 2, bev / 2}, 4, cv::Scalar(255, 255, 255), cv::FILLED);
  const std::pair<const char*, uint16_t> legend[] = {{"road", semantic::kRoad},
                                                     {"sidewalk", semantic::kSidewalk},
                                                     {"terrain", semantic::kTerrain},
                                                     {"building", semantic::kBuilding},
                                                     {"vegetation", semantic::kVegetation},
                                                     {"trunk", semantic::kTrunk},
                                                     {"pole", semantic::kPole},
                                                     {"traffic sign", semantic::kTrafficSign},
                                                     {"car", semantic::kCar},
                                                     {"person", semantic::kPerson},
                                                     {"fence", semantic::kFence},
                                                     {"wall", semantic::kOtherStructure}};
  int y = title_h + range_h + 30;
  for (const auto& [name, cls] : legend) {
    cv::rectangle(img, {bev + 30, y - 14}, {bev + 50, y + 4}, class_colour(cls), cv::FILLED);
    cv::putText(img, name, {bev + 60, y}, cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
    y += 28;
  }
  cv::putText(img,
              rosette ? "top: front view (near = red, far = blue); left: bird's-eye view 100 m x 100 m, forward = up"
                      : "top: range image (near = red, far = blue); left: bird's-eye view 100 m x 100 m, forward = up",
              {bev + 30, y + 20}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
  cv::putText(img, title, {10, 21}, cv::FONT_HERSHEY_SIMPLEX, 0.65, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  write_png(path, img);
}

}  // namespace segmatch::sim
