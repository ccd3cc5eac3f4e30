// libFuzzer target: the pipeline JSON config, as a config file (--config) and as a map's stored
// parameters (what a server and INFO_REPLY's readers parse); the first byte picks which. Bad
// input gives io::IoError naming the origin and the key; anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/error.h>
#include <segmatch/io/pipeline_config.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data + 1), size - 1);
  fuzz::expect_only<io::IoError>([&] {
    if (data[0] & 1) {
      (void)io::parse_map_parameters(text, "fuzz parameters_json");
    } else {
      (void)io::parse_pipeline_config(text, "fuzz.json");
    }
  });
  return 0;
}
