// Exports of a stored segment map for viewing: all segments' points coloured per segment
// (ASCII PLY or PCD, since io's writers carry intensity, not colour) and a top-down PNG.
#pragma once

#include <segmatch/core/segmentation/segment.h>
#include <segmatch/storage/map_types.h>

#include <cstdint>
#include <string>
#include <vector>

namespace segmatch::mapbuilder {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
};

// A saturated colour from the segment id: stable between runs and exports, and neighbouring
// ids (neighbouring objects, usually) get very different hues.
Rgb segment_color(uint64_t id);

// Vertex element with float x y z and uchar red green blue. Throws io::IoError naming the file.
void write_colored_ply(const std::string& path, const Segments& segments);
// FIELDS x y z rgb (rgb packed as PCL does: U4 0x00RRGGBB). Throws io::IoError naming the file.
void write_colored_pcd(const std::string& path, const Segments& segments);

// Top-down picture (north up): segment points coloured per segment, the trajectory as a black
// line and a scale bar. Throws io::IoError naming the file when it cannot be written.
void draw_top_down_png(const std::string& path, const Segments& segments,
                       const std::vector<storage::Keyframe>& trajectory);

}  // namespace segmatch::mapbuilder
