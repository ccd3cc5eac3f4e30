// libFuzzer target: MCAP bags (BagReader's record scan, chunk decompression, message lookup) and
// the CDR decoders, each of which is tried on every message whatever its topic's type, so that
// every decoder sees every kind of payload. Bad input gives io::IoError; anything else is a finding.
#include "fuzz_util.h"

#include <segmatch/io/bag.h>
#include <segmatch/io/error.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  const std::string path = fuzz::write_input("in.mcap", data, size);
  fuzz::expect_only<io::IoError>([&] {
    const std::unique_ptr<io::BagReader> bag = io::BagReader::open(path);
    for (const io::BagTopic& topic : bag->topics()) {
      for (const io::BagMessageRef& ref : bag->messages(topic.name)) {
        std::string cdr;
        fuzz::expect_only<io::IoError>([&] { cdr = bag->data(ref); });
        fuzz::expect_only<io::IoError>([&] { (void)io::decode_point_cloud2(cdr); });
        fuzz::expect_only<io::IoError>([&] { (void)io::decode_odometry(cdr); });
        fuzz::expect_only<io::IoError>([&] { (void)io::decode_pose_stamped(cdr); });
        fuzz::expect_only<io::IoError>([&] { (void)io::decode_tf_message(cdr); });
      }
    }
  });
  return 0;
}
