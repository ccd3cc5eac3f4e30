// libFuzzer target: the trajectory text files: KITTI poses and calibration, TUM trajectories and
// times files (the first byte picks which). Bad input gives io::IoError naming the file and line;
// anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/error.h>
#include <segmatch/io/pose_io.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  if (size == 0) return 0;
  const uint8_t which = data[0] % 4;
  const char* names[] = {"poses.txt", "calib.txt", "poses.tum", "times.txt"};
  const std::string path = fuzz::write_input(names[which], data + 1, size - 1);
  fuzz::expect_only<io::IoError>([&] {
    switch (which) {
      case 0: (void)io::read_kitti_poses(path); break;
      case 1: (void)io::read_kitti_calib(path); break;
      case 2: (void)io::read_tum(path); break;
      default: (void)io::read_times(path); break;
    }
  });
  return 0;
}
