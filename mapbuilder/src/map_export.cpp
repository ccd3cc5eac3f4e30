#include "map_export.h"

#include <segmatch/io/error.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

namespace segmatch::mapbuilder {
namespace {

size_t point_count(const Segments& segments) {
  size_t n = 0;
  for (const Segment& s : segments) n += s.points.size();
  return n;
}

// Calls emit(point, colour) for every point of every segment.
template <class Emit>
void for_each_point(const Segments& segments, Emit emit) {
  for (const Segment& s : segments) {
    const Rgb c = segment_color(s.id);
    for (const Point& p : s.points) emit(p, c);
  }
}

void finish_file(std::ofstream& out, const std::string& path) {
  out.close();
  if (!out) throw io::IoError(path + ": write failed (disk full?)");
}

std::ofstream open_for_writing(const std::string& path) {
  std::ofstream out(path);
  if (!out) throw io::IoError(path + ": cannot open for writing");
  return out;
}

// 1, 2 or 5 times a power of ten, close to a fifth of the picture's width.
double nice_length_m(double width_m) {
  const double target = width_m / 5.0;
  const double decade = std::pow(10.0, std::floor(std::log10(target)));
  for (double step : {5.0, 2.0, 1.0})
    if (step * decade <= target) return step * decade;
  return decade;
}

}  // namespace

Rgb segment_color(uint64_t id) {
  // Golden-ratio steps around the hue circle; OpenCV hue is 0..179.
  const double hue = std::fmod(static_cast<double>(id) * 0.618033988749895, 1.0) * 180.0;
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(hue, 220, 230)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  const cv::Vec3b v = bgr.at<cv::Vec3b>(0, 0);
  return {v[2], v[1], v[0]};
}

void write_colored_ply(const std::string& path, const Segments& segments) {
  std::ofstream out = open_for_writing(path);
  out << "ply\nformat ascii 1.0\ncomment segmatch map segments, coloured per segment\n"
      << "element vertex " << point_count(segments) << "\n"
      << "property float x\nproperty float y\nproperty float z\n"
      << "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  char line[128];
  for_each_point(segments, [&](const Point& p, Rgb c) {
    std::snprintf(line, sizeof line, "%.4f %.4f %.4f %u %u %u\n", p.x, p.y, p.z, c.r, c.g, c.b);
    out << line;
  });
  finish_file(out, path);
}

void write_colored_pcd(const std::string& path, const Segments& segments) {
  std::ofstream out = open_for_writing(path);
  const size_t n = point_count(segments);
  out << "# .PCD v0.7 - segmatch map segments, coloured per segment\nVERSION 0.7\n"
      << "FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
      << "WIDTH " << n << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n << "\nDATA ascii\n";
  char line[128];
  for_each_point(segments, [&](const Point& p, Rgb c) {
    const unsigned rgb = (unsigned(c.r) << 16) | (unsigned(c.g) << 8) | c.b;
    std::snprintf(line, sizeof line, "%.4f %.4f %.4f %u\n", p.x, p.y, p.z, rgb);
    out << line;
  });
  finish_file(out, path);
}

void draw_top_down_png(const std::string& path, const Segments& segments,
                       const std::vector<storage::Keyframe>& trajectory) {
  double min_x = std::numeric_limits<double>::max(), min_y = min_x, max_x = -min_x, max_y = -min_x;
  auto grow = [&](double x, double y) {
    min_x = std::min(min_x, x), max_x = std::max(max_x, x);
    min_y = std::min(min_y, y), max_y = std::max(max_y, y);
  };
  for_each_point(segments, [&](const Point& p, Rgb) { grow(p.x, p.y); });
  for (const storage::Keyframe& k : trajectory)
    grow(k.T_map_sensor.translation().x(), k.T_map_sensor.translation().y());
  if (min_x > max_x) grow(0, 0), grow(10, 10);  // empty map: still a valid picture
  // At most ~1600 px on the long side, never finer than 10 cm per pixel.
  const double m_per_px = std::max(0.1, std::max(max_x - min_x, max_y - min_y) / 1600.0);
  const int margin = 30, bar_room = 40;
  const int width = static_cast<int>((max_x - min_x) / m_per_px) + 2 * margin;
  const int height = static_cast<int>((max_y - min_y) / m_per_px) + 2 * margin + bar_room;
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  auto pixel = [&](double x, double y) {
    return cv::Point(margin + static_cast<int>((x - min_x) / m_per_px),
                     margin + static_cast<int>((max_y - y) / m_per_px));  // north up
  };
  for_each_point(segments, [&](const Point& p, Rgb c) {
    const cv::Point q = pixel(p.x, p.y);
    image.at<cv::Vec3b>(q.y, q.x) = cv::Vec3b(c.b, c.g, c.r);
  });
  std::vector<cv::Point> line;
  for (const storage::Keyframe& k : trajectory)
    line.push_back(pixel(k.T_map_sensor.translation().x(), k.T_map_sensor.translation().y()));
  if (line.size() > 1) cv::polylines(image, line, false, cv::Scalar(0, 0, 0), 2, cv::LINE_AA);

  const double bar_m = nice_length_m(width * m_per_px);
  const cv::Point bar_start(margin, height - margin / 2 - 10);
  const cv::Point bar_end(margin + static_cast<int>(bar_m / m_per_px), bar_start.y);
  cv::line(image, bar_start, bar_end, cv::Scalar(0, 0, 0), 3);
  char label[32];
  std::snprintf(label, sizeof label, "%g m", bar_m);
  cv::putText(image, label, bar_end + cv::Point(8, 5), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 1,
              cv::LINE_AA);
  bool written = false;
  try {
    written = cv::imwrite(path, image);
  } catch (const cv::Exception& e) {
    throw io::IoError(path + ": cannot write the picture: " + e.what());
  }
  if (!written) throw io::IoError(path + ": cannot write the picture (check the folder and the .png extension)");
}

}  // namespace segmatch::mapbuilder
