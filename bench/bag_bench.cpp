// Reading a drive from a ROS 2 bag against reading it from its folder: the same sequence written
// as MCAP bags (zstd, lz4, uncompressed chunks; io::write_sequence_bag), then each read whole as a
// Sequence (open, every scan decoded), as a map builder reads it. Prints seconds per source (the
// median of --repeat runs), scans per second and the ratio to the folder.
#include <segmatch/io/bag.h>
#include <segmatch/io/sequence.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

// Seconds to open `input` and decode every scan; points counted so nothing is optimised away.
double read_all(const std::string& input, size_t* points) {
  const auto start = std::chrono::steady_clock::now();
  const io::Sequence seq = io::Sequence::open(input);
  for (size_t i = 0; i < seq.size(); ++i) *points += seq.scan(i).points.size();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

double median_of(const std::string& input, int repeat, size_t* points) {
  std::vector<double> s;
  for (int r = 0; r < repeat; ++r) s.push_back(read_all(input, points));
  std::sort(s.begin(), s.end());
  return s[s.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"ROS 2 bag reading against the same drive's folder (segmatch-bench-bag)"};
  std::string sequence, work = (fs::temp_directory_path() / "segmatch-bench-bag").string();
  int repeat = 3;
  app.add_option("--sequence", sequence, "a sequence folder (e.g. a segmatch-sim output's sequences/00)")->required();
  app.add_option("--work", work, "folder for the bags written (removed at the end)");
  app.add_option("--repeat", repeat, "runs per source; the median is printed")->check(CLI::Range(1, 20));
  CLI11_PARSE(app, argc, argv);
  try {
    fs::create_directories(work);
    const io::Sequence seq = io::Sequence::open(sequence);
    std::printf("sequence %s: %zu scans\n", sequence.c_str(), seq.size());
    size_t points = 0;
    const double folder_s = median_of(sequence, repeat, &points);
    std::printf("%-22s %8.2f s  %7.1f scans/s\n", "folder", folder_s, seq.size() / folder_s);
    const std::pair<const char*, io::McapCompression> kinds[] = {{"mcap zstd", io::McapCompression::kZstd},
                                                                 {"mcap lz4", io::McapCompression::kLz4},
                                                                 {"mcap none", io::McapCompression::kNone}};
    for (const auto& [name, compression] : kinds) {
      io::SequenceBagOptions o;
      o.mcap.compression = compression;
      const std::string bag = (fs::path(work) / (std::string(name).substr(5) + ".mcap")).string();
      io::write_sequence_bag(seq, bag, o);
      const double s = median_of(bag, repeat, &points);
      std::printf("%-22s %8.2f s  %7.1f scans/s  %.2fx the folder's time  (%.0f MB)\n", name, s, seq.size() / s,
                  s / folder_s, static_cast<double>(fs::file_size(bag)) / 1e6);
      fs::remove(bag);
    }
    std::printf("(%zu points read in all)\n", points);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-bench-bag: %s\n", e.what());
    return 1;
  }
  return 0;
}
