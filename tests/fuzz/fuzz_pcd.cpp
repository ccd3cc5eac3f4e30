// libFuzzer target: the PCD reader (ascii, binary, binary_compressed). Bad input gives
// io::IoError naming the file; anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  const std::string path = fuzz::write_input("in.pcd", data, size);
  fuzz::expect_only<io::IoError>([&] { (void)io::read_pcd(path); });
  return 0;
}
