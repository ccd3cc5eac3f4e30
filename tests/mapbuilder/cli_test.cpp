// segmatch-mapbuilder and segmatch-mapinfo as a user runs them, on a tiny simulated dataset
// generated once for the suite.
#include "segmatch/core/detail/random.h"
#include "segmatch/core/matching/matcher.h"
#include "segmatch/io/cloud_io.h"
#include "segmatch/io/sequence.h"
#include "segmatch/storage/map_reader.h"

#include "segmatch/io/pipeline_config.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "support/fixture_cache.h"
#include "support/run_command.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <random>
#include <sstream>
#include <thread>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

const std::string kBin = SEGMATCH_BIN_DIR;
constexpr int kLast = 40;  // scans 0..40 of sequence 00: a few local clouds, a few seconds

using Result = segmatch::test::CommandResult;
Result run(const std::string& args) { return segmatch::test::run_command(args); }

std::string read_all(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void write_all(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

// A small trained classifier, so that the stored model can be compared byte for byte.
std::string trained_model_bytes() {
  Rng rng(5);
  Segments a(60), b(60);
  std::vector<std::pair<const Segment*, const Segment*>> pairs;
  std::vector<bool> same;
  for (size_t i = 0; i < a.size(); ++i) {
    for (Segment* s : {&a[i], &b[i]}) {
      for (float& f : s->eigen) f = static_cast<float>(rng.uniform());
      for (float& f : s->esf) f = static_cast<float>(rng.uniform());
      s->has_eigen = s->has_esf = true;
    }
    if (i % 2 == 0) b[i] = a[i];
    pairs.emplace_back(&a[i], &b[i]);
    same.push_back(i % 2 == 0);
  }
  MatcherConfig config;
  config.rf_trees = 3;
  RandomForestMatcher rf(config);
  rf.train(pairs, same);
  return rf.save();
}

class MapBuilderCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    std::random_device rd;
    dir_ = fs::temp_directory_path() / ("segmatch_mapbuilder_test_" + std::to_string(rd()));
    fs::create_directories(dir_);
    // The dataset and the map are built once for every test process (support/fixture_cache.h).
    const fs::path data = test::cached_fixture("mapbuilder-data", {kBin + "/segmatch-sim"}, [](const fs::path& folder) {
      const Result simulated = run(kBin +
                                   "/segmatch-sim --preset tiny --seed 3 --length-00-m 100 --length-01-m 50 "
                                   "--no-images --out " +
                                   folder.string());
      if (simulated.code != 0) throw std::runtime_error("segmatch-sim failed: " + simulated.output);
    });
    sequence_ = data / "sequences/00";
    const fs::path maps = test::cached_fixture(
        "mapbuilder-map", {kBin + "/segmatch-mapbuilder", data / ".complete"}, [](const fs::path& folder) {
          write_all(folder / "model.yml", trained_model_bytes());
          fs::create_directories(folder / "map");  // the map alone, to see that no temporary file is left
          const Result built = run(builder() + " --classifier " + (folder / "model.yml").string() +
                                   " --name tiny-00 --output " + (folder / "map/tiny.sqlite").string());
          write_all(folder / "built.log", std::to_string(built.code) + "\n" + built.output);
        });
    map_path_ = maps / "map/tiny.sqlite";
    model_path_ = maps / "model.yml";
    const fs::path log = maps / "built.log";
    const std::string text = read_all(log);
    built_.code = std::stoi(text.substr(0, text.find('\n')));
    built_.output = text.substr(text.find('\n') + 1);
    std::printf("%s", built_.output.c_str());
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static fs::path sequence() { return sequence_; }
  static fs::path map_path() { return map_path_; }
  static std::string builder(int last = kLast) {
    return kBin + "/segmatch-mapbuilder --input " + sequence().string() + " --last " + std::to_string(last);
  }
  static std::vector<std::string> folder_entries(const fs::path& folder) {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(folder)) names.push_back(e.path().filename().string());
    return names;
  }

  static fs::path dir_, sequence_, map_path_, model_path_;
  static Result built_;
};
fs::path MapBuilderCli::dir_, MapBuilderCli::sequence_, MapBuilderCli::map_path_, MapBuilderCli::model_path_;
Result MapBuilderCli::built_;

// CTest's MapBuilderFixture entry builds the shared dataset and map first (the suite's
// FIXTURES_SETUP), so that the other entries find them built instead of waiting on the lock.
class MapBuilderFixture : public MapBuilderCli {};

}  // namespace

TEST_F(MapBuilderFixture, TheSharedDatasetAndMapAreBuilt) {
  EXPECT_EQ(built_.code, 0) << built_.output;
  EXPECT_TRUE(fs::exists(map_path()));
  EXPECT_TRUE(fs::exists(sequence() / "poses.txt"));
}

TEST_F(MapBuilderCli, WritesAReadableMapWithTrajectoryClassifierAndParameters) {
  ASSERT_EQ(built_.code, 0) << built_.output;
  const storage::MapReader map = storage::MapReader::open(map_path().string());
  const storage::MapStats stats = map.stats();
  EXPECT_GT(stats.segments, 10u);
  EXPECT_EQ(stats.keyframes, static_cast<size_t>(kLast + 1)) << "one keyframe per scan used";
  EXPECT_EQ(map.metadata().name, "tiny-00");
  EXPECT_NE(map.metadata().parameters_json.find("\"segment_map\""), std::string::npos);
  EXPECT_NE(map.metadata().tool_version.find("segmatch-mapbuilder"), std::string::npos);
  const auto classifier = map.classifier();
  ASSERT_TRUE(classifier.has_value());
  EXPECT_EQ(classifier->format, "opencv-rtrees-yaml");
  EXPECT_EQ(classifier->bytes, read_all(model_path_));

  // The trajectory is the sequence's poses; every segment refers to one of its keyframes.
  const io::Sequence seq = io::Sequence::open(sequence().string());
  const std::vector<storage::Keyframe> trajectory = map.trajectory();
  ASSERT_EQ(trajectory.size(), static_cast<size_t>(kLast + 1));
  EXPECT_TRUE(trajectory[kLast].T_map_sensor.isApprox(seq.poses()[kLast]));
  EXPECT_DOUBLE_EQ(trajectory[kLast].time_s, seq.times()[kLast]);
  std::vector<uint32_t> keyframes;
  map.load_segments(&keyframes);
  for (uint32_t k : keyframes) EXPECT_LE(k, static_cast<uint32_t>(kLast));
  EXPECT_TRUE(map.check_integrity().empty());
  EXPECT_EQ(folder_entries(map_path().parent_path()).size(), 1u) << "no temporary file left";
  EXPECT_NE(built_.output.find("local clouds:"), std::string::npos) << "summary printed";
  // No preset given: the auto profile measured the simulated HDL-64E scans, said so, and stored
  // the measurements with the parameters.
  EXPECT_NE(built_.output.find("sensor class: dense-spinning"), std::string::npos) << built_.output;
  EXPECT_NE(map.metadata().parameters_json.find("\"measured\""), std::string::npos);
}

TEST_F(MapBuilderCli, PrintConfigWritesTheChosenProfileAsAReusableConfig) {
  const Result r = run(builder() + " --print-config");
  ASSERT_EQ(r.code, 0) << r.output;
  // stdout holds the JSON; what was measured goes to stderr (folded in here, before it).
  ASSERT_NE(r.output.find('{'), std::string::npos) << r.output;
  const io::PipelineConfig printed = io::parse_pipeline_config(r.output.substr(r.output.find('{')), "printed config");
  EXPECT_EQ(printed.preset, "auto");
  ASSERT_TRUE(printed.measured.has_value());
  EXPECT_EQ(printed.measured->sensor_class(), "dense-spinning");
  const storage::MapReader map = storage::MapReader::open(map_path().string());
  EXPECT_EQ(io::to_json(printed), io::to_json(io::parse_pipeline_config(map.metadata().parameters_json, "map")));
}

// A profile whose parameters keep nothing must not leave a map that localizes nothing: the
// builder refuses, names the sensor class and the parameters, writes nothing and keeps an
// existing map; a sparse map is refused by the per-km floor, which 0 lifts.
TEST_F(MapBuilderCli, AMapWithNoOrTooFewSegmentsIsRefusedNamingTheProfile) {
  const Result printed = run(builder() + " --print-config 2>/dev/null");
  ASSERT_EQ(printed.code, 0) << printed.output;
  nlohmann::json config = nlohmann::json::parse(printed.output.substr(printed.output.find('{')));
  config["voxel"]["min_points_per_voxel"] = 1000;
  write_all(dir_ / "empty.json", config.dump());
  const fs::path out = dir_ / "empty.sqlite";
  Result r = run(builder() + " --config " + (dir_ / "empty.json").string() + " --output " + out.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("kept 0 segments"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("sensor class dense-spinning"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("voxels 0.10 m with >= 1000 points"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("--min-segments-per-km 0"), std::string::npos) << "no way around an empty map: " << r.output;
  EXPECT_FALSE(fs::exists(out));

  const fs::path kept = dir_ / "kept.sqlite";
  fs::copy_file(map_path(), kept);
  const std::string before = read_all(kept);
  r = run(builder() + " --no-classifier --min-segments-per-km 1e7 --force --output " + kept.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("expected; no map written"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--min-segments-per-km 0 writes this sparse map anyway"), std::string::npos) << r.output;
  EXPECT_EQ(read_all(kept), before);
  for (const std::string& name : folder_entries(dir_))
    EXPECT_TRUE(name.rfind("kept.sqlite", 0) != 0 || name == "kept.sqlite") << "left behind: " << name;
  r = run(builder() + " --no-classifier --min-segments-per-km 0 --force --output " + kept.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(read_all(kept), before);
}

// Points are 32-bit floats: poses 2000 km from the origin (UTM-like) would quantise them to
// 12.5 cm, so the builder says to subtract a local origin.
TEST_F(MapBuilderCli, WarnsWhenPosesAreFarFromTheOrigin) {
  const fs::path far = dir_ / "far";
  fs::create_directories(far);
  for (const auto& e : fs::directory_iterator(sequence()))
    if (e.path().filename() != "poses.txt" && e.path().filename() != "odom_poses.txt")
      fs::create_symlink(e.path(), far / e.path().filename());
  std::ifstream in(sequence() / "poses.txt");
  std::ofstream out(far / "poses.txt");
  for (std::string line; std::getline(in, line);) {
    std::istringstream fields(line);
    double v[12];
    for (double& x : v) fields >> x;
    v[3] += 2e6;
    for (int i = 0; i < 12; ++i) out << std::setprecision(17) << v[i] << (i < 11 ? ' ' : '\n');
  }
  out.close();
  const Result r = run(kBin + "/segmatch-mapbuilder --input " + far.string() + " --last 2 --output " +
                       (dir_ / "far.sqlite").string());
  EXPECT_NE(r.output.find("warning: the poses reach 2000 km from the origin"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("subtract a local origin"), std::string::npos) << r.output;
}

TEST_F(MapBuilderCli, MapinfoPrintsTheCountsAndCheckPasses) {
  const storage::MapStats stats = storage::MapReader::open(map_path().string()).stats();
  const Result info = run(kBin + "/segmatch-mapinfo " + map_path().string() + " --check");
  ASSERT_EQ(info.code, 0) << info.output;
  EXPECT_NE(info.output.find("segments:       " + std::to_string(stats.segments) + "\n"), std::string::npos)
      << info.output;
  EXPECT_NE(info.output.find("points:         " + std::to_string(stats.points) + "\n"), std::string::npos);
  EXPECT_NE(info.output.find("keyframes:      " + std::to_string(stats.keyframes) + "\n"), std::string::npos);
  EXPECT_NE(info.output.find("name:           tiny-00"), std::string::npos);
  EXPECT_NE(info.output.find("integrity:      ok"), std::string::npos);
  EXPECT_NE(info.output.find("classifier:     opencv-rtrees-yaml"), std::string::npos);
}

TEST_F(MapBuilderCli, MapinfoCheckFailsOnADamagedMap) {
  const fs::path damaged = dir_ / "damaged.sqlite";
  std::string bytes = read_all(map_path());
  bytes.resize(bytes.size() / 2);  // truncated: a copy cut short
  write_all(damaged, bytes);
  const Result info = run(kBin + "/segmatch-mapinfo " + damaged.string() + " --check");
  EXPECT_EQ(info.code, 1) << info.output;
  EXPECT_NE(info.output.find(damaged.string()), std::string::npos) << "names the file: " << info.output;
  fs::remove(damaged);
}

// An old map is read, said to be old with the command that upgrades it, and upgraded.
TEST_F(MapBuilderCli, MapinfoUpgradesASchemaOneMap) {
  const std::string old_map = SEGMATCH_OLD_MAP_FOR_TEST;
  Result r = run(kBin + "/segmatch-mapinfo " + old_map);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("schema version: 1 (older"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("segmatch-mapinfo --upgrade OLD NEW"), std::string::npos) << r.output;
  const fs::path upgraded = dir_ / "upgraded.sqlite";
  r = run(kBin + "/segmatch-mapinfo --upgrade " + old_map + " " + upgraded.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string schema = std::to_string(storage::kSchemaVersion);
  EXPECT_NE(r.output.find("(schema " + schema + ","), std::string::npos) << r.output;
  r = run(kBin + "/segmatch-mapinfo " + upgraded.string() + " --check");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("schema version: " + schema + "\n"), std::string::npos) << r.output;
  // An existing target is kept unless --overwrite; upgrading a current map says there is nothing to do.
  r = run(kBin + "/segmatch-mapinfo --upgrade " + old_map + " " + upgraded.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("already exists"), std::string::npos) << r.output;
  r = run(kBin + "/segmatch-mapinfo --upgrade " + upgraded.string() + " " + (dir_ / "again.sqlite").string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("nothing to upgrade"), std::string::npos) << r.output;
  fs::remove(upgraded);
}

TEST_F(MapBuilderCli, MapinfoExportsColouredPointsAndAPicture) {
  const storage::MapStats stats = storage::MapReader::open(map_path().string()).stats();
  const fs::path ply = dir_ / "segments.ply", pcd = dir_ / "segments.pcd", png = dir_ / "top.png";
  Result r = run(kBin + "/segmatch-mapinfo " + map_path().string() + " --export-ply " + ply.string() + " --png " +
                 png.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(io::read_ply(ply.string()).points.size(), stats.points);
  EXPECT_NE(read_all(ply).find("property uchar red"), std::string::npos);
  const std::string picture = read_all(png);
  ASSERT_GT(picture.size(), 1000u);
  EXPECT_EQ(picture.substr(1, 3), "PNG");
  r = run(kBin + "/segmatch-mapinfo " + map_path().string() + " --export-pcd " + pcd.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(io::read_pcd(pcd.string()).points.size(), stats.points);
}

TEST_F(MapBuilderCli, ASecondBuildWithoutForceIsRefusedAndTheMapKept) {
  const std::string before = read_all(map_path());
  const auto mtime = fs::last_write_time(map_path());
  const Result r = run(builder() + " --no-classifier --output " + map_path().string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("already exists"), std::string::npos) << r.output;
  EXPECT_EQ(read_all(map_path()), before);
  EXPECT_EQ(fs::last_write_time(map_path()), mtime);
}

TEST_F(MapBuilderCli, ForceReplacesAMap) {
  const fs::path other = dir_ / "forced.sqlite";
  write_all(other, "not a map yet");
  const Result r = run(builder(20) + " --no-classifier --force --output " + other.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const storage::MapReader map = storage::MapReader::open(other.string());
  EXPECT_EQ(map.stats().keyframes, 21u);
  EXPECT_FALSE(map.stats().has_classifier);
  fs::remove(other);
}

TEST_F(MapBuilderCli, BadRangesAreRefused) {
  const fs::path out = dir_ / "range.sqlite";
  Result r = run(kBin + "/segmatch-mapbuilder --input " + sequence().string() + " --first 20 --last 10 --output " +
                 out.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("empty scan range"), std::string::npos) << r.output;
  r = run(builder(1000000) + " --output " + out.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--last 1000000 is past the last scan"), std::string::npos) << r.output;
  r = run(builder() + " --stride 0 --output " + out.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(MapBuilderCli, AMissingInputFolderIsRefusedWithAMessage) {
  const fs::path out = dir_ / "missing.sqlite";
  const Result r =
      run(kBin + "/segmatch-mapbuilder --input " + (dir_ / "no-such-seq").string() + " --output " + out.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no-such-seq does not exist"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(MapBuilderCli, AnUnreadableScanIsAnErrorNamingTheFile) {
  // A copy of the sequence whose scan 3 is truncated mid-record.
  const fs::path copy = dir_ / "broken-seq";
  fs::create_directories(copy / "velodyne");
  for (const char* f : {"poses.txt", "calib.txt", "times.txt"}) fs::copy_file(sequence() / f, copy / f);
  const io::Sequence seq = io::Sequence::open(sequence().string());
  for (size_t i = 0; i < seq.size(); ++i)
    fs::create_symlink(seq.scan_path(i), copy / "velodyne" / fs::path(seq.scan_path(i)).filename());
  const fs::path bad = copy / "velodyne/000003.bin";
  fs::remove(bad);
  write_all(bad, read_all(seq.scan_path(3)).substr(0, 100));
  const fs::path out = dir_ / "broken.sqlite";
  const Result r = run(kBin + "/segmatch-mapbuilder --input " + copy.string() + " --last 10 --output " + out.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("000003.bin"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  for (const std::string& name : folder_entries(dir_))
    EXPECT_EQ(name.find("broken.sqlite.tmp-"), std::string::npos) << "temporary file left: " << name;
  fs::remove_all(copy);
}

TEST_F(MapBuilderCli, BadConfigAndModelFilesAreRefusedNamingTheProblem) {
  const fs::path out = dir_ / "config.sqlite", config = dir_ / "bad.json", junk = dir_ / "junk.yml";
  write_all(config, R"({"voxel": {"leaf_mm": 0.2}})");
  Result r = run(builder() + " --config " + config.string() + " --output " + out.string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.output.find("leaf_mm"), std::string::npos) << r.output;
  r = run(builder() + " --classifier " + (dir_ / "none.yml").string() + " --output " + out.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("none.yml"), std::string::npos) << r.output;
  write_all(junk, "this is no model");
  r = run(builder() + " --classifier " + junk.string() + " --output " + out.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("junk.yml: not a valid classifier model"), std::string::npos) << r.output;
  r = run(builder() + " --preset no-such-preset --output " + out.string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(MapBuilderCli, WithoutTheDefaultModelTheMapHasNoClassifierAndSaysSo) {
  const fs::path out = dir_ / "default.sqlite";
  const Result r = run(builder(10) + " --output " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const bool default_exists = fs::exists(SEGMATCH_DEFAULT_MODEL_FOR_TEST);
  EXPECT_EQ(storage::MapReader::open(out.string()).stats().has_classifier, default_exists);
  EXPECT_EQ(r.output.find("warning: default classifier") != std::string::npos, !default_exists) << r.output;
  fs::remove(out);
}

// Starts a full build, signals it once its temporary map exists, and checks that it leaves
// nothing behind; with `existing`, a file already at the target (replaced with --force) must
// survive unchanged.
void interrupt_build(const fs::path& sequence, const fs::path& folder, int signal, bool existing) {
  fs::create_directories(folder);
  const fs::path out = folder / "map.sqlite", log = folder.parent_path() / "interrupt.log";
  if (existing) write_all(out, "the previous map");
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1), dup2(fd, 2);
    const std::string bin = kBin + "/segmatch-mapbuilder";
    execl(bin.c_str(), bin.c_str(), "--input", sequence.c_str(), "--output", out.c_str(), "--no-classifier",
          existing ? "--force" : static_cast<char*>(nullptr), static_cast<char*>(nullptr));
    _exit(127);
  }
  bool began = false;
  for (int i = 0; i < 3000 && !began; ++i) {  // up to 60 s: the recording is measured first (seconds under load)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    for (const auto& e : fs::directory_iterator(folder))
      began = began || e.path().string().find(".tmp-") != std::string::npos;
  }
  EXPECT_TRUE(began) << "the build started writing its temporary map";
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // inside the build loop
  kill(pid, signal);
  int status = 0;
  waitpid(pid, &status, 0);
  const std::string output = read_all(log);
  ASSERT_TRUE(WIFEXITED(status)) << "exits by itself, not killed by the signal: " << output;
  EXPECT_EQ(WEXITSTATUS(status), 128 + signal) << output;
  EXPECT_NE(output.find("interrupted, no map written"), std::string::npos) << output;
  if (existing) {
    EXPECT_EQ(read_all(out), "the previous map");
    EXPECT_EQ(std::distance(fs::directory_iterator(folder), fs::directory_iterator()), 1) << "no temporary file left";
  } else {
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(fs::is_empty(folder)) << "no temporary file left behind";
  }
}

TEST_F(MapBuilderCli, AnInterruptedBuildLeavesNoFileSigint) {
  interrupt_build(sequence(), dir_ / "sigint", SIGINT, false);
}

TEST_F(MapBuilderCli, AnInterruptedForcedBuildKeepsTheExistingMapSigterm) {
  interrupt_build(sequence(), dir_ / "sigterm", SIGTERM, true);
}
