// libFuzzer target: the PLY reader (ascii, binary little- and big-endian). Bad input gives
// io::IoError naming the file; anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/cloud_io.h>
#include <segmatch/io/error.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  const std::string path = fuzz::write_input("in.ply", data, size);
  fuzz::expect_only<io::IoError>([&] { (void)io::read_ply(path); });
  return 0;
}
