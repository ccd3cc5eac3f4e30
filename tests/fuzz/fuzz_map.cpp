// libFuzzer target: a map file. It is opened, checked, and every part a server or a tool reads is
// decoded: metadata, the classifier's bytes, the segments with and without points, each segment's
// points one by one (as a lazy server reads them), segments_near and the integrity check. Bad
// input gives storage::StorageError naming the file; anything else is a finding. Seeds are small
// valid maps (tests/fuzz/corpus/map), so that mutations reach past SQLite's header.
#include "fuzz_util.h"

#include <segmatch/storage/map_reader.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace segmatch;
  const std::string path = fuzz::write_input("map.sqlite", data, size);
  fuzz::expect_only<storage::StorageError>([&] {
    const storage::MapReader reader = storage::MapReader::open(path);
    (void)reader.stats();
    (void)reader.classifier();
    (void)reader.check_integrity();
    const Segments described = reader.load_segments_without_points();
    for (size_t i = 0; i < described.size(); ++i) (void)reader.read_points(i);
    (void)reader.load_segments();
    (void)reader.segments_near(Eigen::Vector3f::Zero(), 50.f);
  });
  return 0;
}
