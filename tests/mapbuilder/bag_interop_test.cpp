// ROS 2 bags in, against an independent writer: bags written by the npm packages @mcap/core and
// @foxglove/rosmsg2-serialization (tests/tools/bagwriter, Node.js) from a simulated drive, in both
// compressions, unchunked, with other PointCloud2 field orders, as a rosbag2 .db3, and with poses
// on /tf, each give the map the same drive's PCD folder gives: the same segments at the same
// places. Skips with a message when Node.js or the writer's packages are missing (scripts/test.sh
// installs them).
#include "segmatch/storage/map_reader.h"

#include <gtest/gtest.h>

#include "support/fixture_cache.h"
#include "support/run_command.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

const std::string kBin = SEGMATCH_BIN_DIR;
const fs::path kWriter = fs::path(SEGMATCH_SOURCE_DIR) / "tests/tools/bagwriter";

test::CommandResult run(const std::string& args) { return test::run_command(args); }

class BagInterop : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    keyframes_ = test::cached_fixture("bag-interop-data", {kBin + "/segmatch-sim"},
                                      [](const fs::path& folder) {
                                        const test::CommandResult r =
                                            run(kBin +
                                                "/segmatch-sim --preset tiny --seed 3 --length-00-m 100 "
                                                "--length-01-m 50 --no-images --keyframes-every-m 2 --out " +
                                                folder.string());
                                        if (r.code != 0) throw std::runtime_error("segmatch-sim failed: " + r.output);
                                      }) /
                 "keyframes/00";
    dir_ = fs::temp_directory_path() / ("segmatch_bag_interop_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    reference_ = build((dir_ / "folder.sqlite").string(), keyframes_.string(), "");
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  void SetUp() override {
    if (run("node --version").code != 0)
      GTEST_SKIP() << "Node.js is not installed (scripts/install-deps.sh installs it)";
    if (!fs::exists(kWriter / "node_modules/@mcap/core"))
      GTEST_SKIP() << "the bag writer's packages are not installed: npm ci in " << kWriter.string()
                   << " (scripts/test.sh does)";
  }

  // The map of `input` (a folder or a bag) with extra mapbuilder flags; its segments.
  static Segments build(const std::string& map, const std::string& input, const std::string& flags) {
    const test::CommandResult r =
        run(kBin + "/segmatch-mapbuilder --no-classifier --min-segments-per-km 0 --force --input " + input + " " +
            flags + " -o " + map);
    if (r.code != 0) throw std::runtime_error("segmatch-mapbuilder failed on " + input + ": " + r.output);
    return storage::MapReader::open(map).load_segments_without_points();
  }

  // Writes the drive with the independent writer, builds its map, compares it with the folder's.
  static void expect_same_map(const std::string& name, const std::string& writer_flags,
                              const std::string& builder_flags) {
    const fs::path bag = dir_ / name;
    const test::CommandResult w = run("node " + (kWriter / "write_bag.mjs").string() + " --sequence " +
                                      keyframes_.string() + " --out " + bag.string() + " " + writer_flags);
    ASSERT_EQ(w.code, 0) << w.output;
    const Segments segments = build((dir_ / (name + ".sqlite")).string(), bag.string(), builder_flags);
    ASSERT_FALSE(reference_.empty());
    ASSERT_EQ(segments.size(), reference_.size()) << name;
    double worst_m = 0.0;
    for (size_t i = 0; i < segments.size(); ++i)
      worst_m = std::max(worst_m, static_cast<double>((segments[i].centroid - reference_[i].centroid).norm()));
    EXPECT_LT(worst_m, 1e-3) << name << ": segments moved";
  }

  static fs::path dir_, keyframes_;
  static Segments reference_;
};
fs::path BagInterop::dir_, BagInterop::keyframes_;
Segments BagInterop::reference_;

}  // namespace

TEST_F(BagInterop, ZstdChunks) { expect_same_map("zstd.mcap", "--compression zstd", ""); }
TEST_F(BagInterop, Lz4Chunks) { expect_same_map("lz4.mcap", "--compression lz4", ""); }
TEST_F(BagInterop, UncompressedChunks) { expect_same_map("none.mcap", "--compression none", ""); }
TEST_F(BagInterop, Unchunked) { expect_same_map("unchunked.mcap", "--unchunked", ""); }
TEST_F(BagInterop, IntensityFirst) { expect_same_map("ixyz.mcap", "--field-order ixyz", "--points-topic /points"); }
TEST_F(BagInterop, DoublesAndARing) {
  expect_same_map("f64.mcap", "--field-order xyz_ring_i_f64", "--pose-topic /odom");
}
TEST_F(BagInterop, Rosbag2Sqlite) { expect_same_map("db3", "--format db3", ""); }
TEST_F(BagInterop, PosesFromTf) { expect_same_map("tf.mcap", "--tf", "--map-frame map"); }
