#include "segmatch/sim/dataset.h"

#include "segmatch/io/cloud_io.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/io/sequence.h"

#include <gtest/gtest.h>

#include "sim_test_util.h"

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>

using namespace segmatch;
using namespace segmatch::sim;
namespace fs = std::filesystem;

namespace {

using segmatch::sim_test::read_all;
using segmatch::sim_test::TempDir;

std::map<std::string, std::string> all_files(const fs::path& root) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(root))
    if (e.is_regular_file()) out[fs::relative(e.path(), root).string()] = read_all(e.path());
  return out;
}

// A small but complete dataset: the tiny world with a 16-beam sensor keeps tests fast.
DatasetConfig small(uint64_t seed, double first_m, double second_m) {
  DatasetConfig c = dataset_preset("tiny", seed);
  c.sensor = "vlp16";
  c.first_length_m = first_m;
  c.second_length_m = second_m;
  return c;
}

}  // namespace

TEST(Dataset, WritesKittiLayoutThatTheSequenceReaderLoads) {
  TempDir dir("segmatch_sim_test_");
  const DatasetConfig c = small(21, 300, 160);
  size_t calls = 0;
  const DatasetSummary s =
      generate_dataset(c, dir.path().string(), [&](const std::string&, size_t, size_t) { ++calls; });
  EXPECT_GT(calls, 2u) << "progress is reported";
  for (const char* f : {"world.png", "scan.png", "dataset.json", "ground_truth/lidar_poses_00.txt",
                        "ground_truth/lidar_poses_01.txt", "ground_truth/revisits_01_00.txt",
                        "ground_truth/objects_00.csv", "sequences/00/calib.txt", "sequences/01/times.txt"})
    EXPECT_TRUE(fs::exists(dir.path() / f)) << f;

  const Poses T_world_lidar = io::read_kitti_poses((dir.path() / "ground_truth/lidar_poses_00.txt").string());
  const io::Sequence seq = io::Sequence::open((dir.path() / "sequences/00").string());
  ASSERT_EQ(seq.size(), s.scans[0]);
  ASSERT_EQ(T_world_lidar.size(), s.scans[0]);
  EXPECT_TRUE(seq.has_labels());
  EXPECT_TRUE(seq.has_times());
  // poses.txt is in the KITTI camera frame; converted back with calib.txt it must equal the
  // ground truth LiDAR poses relative to the first scan.
  for (size_t i = 0; i < seq.size(); i += 17) {
    const Pose3d expected = T_world_lidar[0].inverse() * T_world_lidar[i];
    EXPECT_TRUE(seq.poses()[i].isApprox(expected, 1e-6)) << "scan " << i;
  }
  const io::CloudData scan = seq.scan(seq.size() / 2);
  ASSERT_GT(scan.points.size(), 5000u);
  ASSERT_EQ(scan.labels.size(), scan.points.size());
  std::set<uint16_t> classes;
  for (size_t i = 0; i < scan.points.size(); ++i) {
    const double r = scan.points[i].xyz().norm();
    EXPECT_GT(r, 0.5);
    EXPECT_LT(r, 101.0);
    classes.insert(label_class(scan.labels[i]));
  }
  EXPECT_TRUE(classes.count(semantic::kRoad));
  EXPECT_GE(classes.size(), 5u);
}

TEST(Dataset, SecondTraversalRevisitsTheFirst) {
  TempDir dir("segmatch_sim_test_");
  const DatasetSummary s = generate_dataset(small(21, 300, 160), dir.path().string());
  std::ifstream f(dir.path() / "ground_truth/revisits_01_00.txt");
  std::string line;
  size_t rows = 0, close = 0;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    int frame, ref;
    double dist, heading;
    ASSERT_EQ(std::sscanf(line.c_str(), "%d %d %lf %lf", &frame, &ref, &dist, &heading), 4) << line;
    EXPECT_EQ(frame, static_cast<int>(rows));
    EXPECT_LT(ref, static_cast<int>(s.scans[0]));
    close += dist < 5.0;
    ++rows;
  }
  EXPECT_EQ(rows, s.scans[1]);
  EXPECT_EQ(close, s.revisit_frames);
  EXPECT_GT(close, rows / 4);
}

TEST(Dataset, SameSeedSameBytesWhateverTheThreadCount) {
  TempDir a("segmatch_sim_test_"), b("segmatch_sim_test_"), other("segmatch_sim_test_");
  DatasetConfig c = small(5, 60, 60);
  c.threads = 1;
  generate_dataset(c, a.path().string());
  c.threads = 2;
  generate_dataset(c, b.path().string());
  const auto files_a = all_files(a.path()), files_b = all_files(b.path());
  ASSERT_EQ(files_a.size(), files_b.size());
  ASSERT_GT(files_a.size(), 100u);
  for (const auto& [name, bytes] : files_a) {
    auto it = files_b.find(name);
    ASSERT_NE(it, files_b.end()) << name;
    EXPECT_TRUE(bytes == it->second) << name << " differs";
  }
  generate_dataset(small(6, 60, 60), other.path().string());
  EXPECT_NE(read_all(a.path() / "sequences/00/velodyne/000000.bin"),
            read_all(other.path() / "sequences/00/velodyne/000000.bin"));
}

TEST(Dataset, InvalidConfigurationIsRefusedBeforeAnythingIsWritten) {
  TempDir dir("segmatch_sim_test_");
  DatasetConfig c = small(1, 60, 60);
  c.sensor = "hdl128";
  EXPECT_THROW(generate_dataset(c, (dir.path() / "x").string()), std::invalid_argument);
  EXPECT_FALSE(fs::exists(dir.path() / "x"));
  EXPECT_THROW(dataset_preset("huge", 1), std::invalid_argument);
}

TEST(SimCli, RefusesToOverwriteWithoutForceAndRejectsBadArguments) {
  const std::string bin = std::string(SEGMATCH_BIN_DIR) + "/segmatch-sim";
  if (!fs::exists(bin)) GTEST_SKIP() << bin << " not built";
  TempDir dir("segmatch_sim_test_");
  std::ofstream(dir.path() / "keep.txt") << "user data";
  const std::string out = dir.path().string();
  auto run = [](const std::string& cmd) { return WEXITSTATUS(std::system((cmd + " > /dev/null 2>&1").c_str())); };
  EXPECT_NE(run(bin + " --preset tiny --sensor vlp16 --length-00-m 60 --length-01-m 60 --out " + out), 0);
  EXPECT_TRUE(fs::exists(dir.path() / "keep.txt"));
  EXPECT_FALSE(fs::exists(dir.path() / "sequences"));
  EXPECT_NE(run(bin + " --preset nowhere --out " + out + "/y"), 0);
  EXPECT_NE(run(bin + " --sensor hdl128 --out " + out + "/z"), 0);
  EXPECT_EQ(
      run(bin + " --preset tiny --sensor vlp16 --length-00-m 60 --length-01-m 60 --no-images --out " + out + "/ok"), 0);
  EXPECT_TRUE(fs::exists(dir.path() / "ok/sequences/01/velodyne/000000.bin"));
}
