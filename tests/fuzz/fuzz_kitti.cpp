// libFuzzer target: KITTI velodyne .bin scans and SemanticKITTI .label files (the first byte
// picks which). Bad input gives io::IoError naming the file; anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  if (size == 0) return 0;
  const bool labels = data[0] & 1;
  const std::string path = fuzz::write_input(labels ? "in.label" : "in.bin", data + 1, size - 1);
  fuzz::expect_only<io::IoError>([&] {
    if (labels) {
      (void)io::read_kitti_labels(path);
    } else {
      (void)io::read_kitti_bin(path);
    }
  });
  return 0;
}
