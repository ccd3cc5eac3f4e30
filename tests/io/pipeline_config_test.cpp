#include "segmatch/io/pipeline_config.h"

#include "segmatch/io/error.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>

using namespace segmatch;
using namespace segmatch::io;

namespace {

std::string error_of(const std::string& json_text) {
  try {
    parse_pipeline_config(json_text, "cfg.json");
  } catch (const IoError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(PipelineConfig, DefaultsAreThePapers) {
  const PipelineConfig c = parse_pipeline_config("{}", "cfg.json");
  EXPECT_EQ(c.preset, "kitti-hdl64");
  EXPECT_DOUBLE_EQ(c.local_cloud.radius_m, 60.0);
  EXPECT_FLOAT_EQ(c.localizer.segmentation.voxel.leaf_m, 0.1f);
  EXPECT_EQ(c.localizer.segmentation.voxel.min_points_per_voxel, 2);
  EXPECT_FLOAT_EQ(c.localizer.segmentation.segmenter.cluster_distance_m, 0.2f);
  EXPECT_EQ(c.localizer.segmentation.segmenter.min_points, 100);
  EXPECT_EQ(c.localizer.segmentation.segmenter.max_points, 15000);
  EXPECT_EQ(c.localizer.retrieval.k, 200);
  EXPECT_EQ(c.localizer.matcher.rf_trees, 25);
  EXPECT_FLOAT_EQ(c.localizer.verification.resolution_m, 0.4f);
  EXPECT_EQ(c.localizer.verification.min_inliers, 4);
}

TEST(PipelineConfig, JsonRoundTripKeepsEveryField) {
  PipelineConfig c = pipeline_preset("sparse-keyframes");
  c.local_cloud.radius_m = 42.5;
  c.localizer.segmentation.ground.method = GroundRemoval::kHeightThreshold;
  c.localizer.segmentation.segmenter.type = SegmenterType::kRegionGrowing;
  c.localizer.segmentation.descriptors.esf_seed = 0xFFFFFFFFFFFFull;
  c.localizer.matcher.type = MatcherType::kL2;
  c.localizer.matcher.use_shapes = false;
  c.localizer.refine_pose = false;
  c.localizer.verification.seed = 99;
  c.segment_map.duplicate_distance_m = 0.75f;
  const std::string text = to_json(c);
  const PipelineConfig back = parse_pipeline_config(text, "roundtrip");
  EXPECT_EQ(to_json(back), text);
  EXPECT_EQ(back.preset, "sparse-keyframes");
  EXPECT_DOUBLE_EQ(back.local_cloud.radius_m, 42.5);
  EXPECT_EQ(back.localizer.segmentation.ground.method, GroundRemoval::kHeightThreshold);
  EXPECT_EQ(back.localizer.segmentation.segmenter.type, SegmenterType::kRegionGrowing);
  EXPECT_EQ(back.localizer.segmentation.descriptors.esf_seed, 0xFFFFFFFFFFFFull);
  EXPECT_EQ(back.localizer.matcher.type, MatcherType::kL2);
  EXPECT_FALSE(back.localizer.refine_pose);
  EXPECT_FLOAT_EQ(back.segment_map.duplicate_distance_m, 0.75f);
}

TEST(PipelineConfig, RangeImageSegmenterAndItsFields) {
  const PipelineConfig c = parse_pipeline_config(
      R"({"segmenter": {"type": "range_image", "range_image_beta_deg": 8, "range_image_rows": 64,
          "range_image_azimuth_step_deg": 0.2}})",
      "cfg");
  const SegmenterConfig& s = c.localizer.segmentation.segmenter;
  EXPECT_EQ(s.type, SegmenterType::kRangeImage);
  EXPECT_FLOAT_EQ(s.range_image_beta_deg, 8.0f);
  EXPECT_EQ(s.range_image_rows, 64);
  EXPECT_FLOAT_EQ(s.range_image_azimuth_step_deg, 0.2f);
  EXPECT_EQ(to_json(parse_pipeline_config(to_json(c), "roundtrip")), to_json(c));
  EXPECT_THROW(parse_pipeline_config(R"({"segmenter": {"range_image_beta_deg": 95}})", "cfg"), std::exception);
}

TEST(PipelineConfig, PresetThenOverrides) {
  const PipelineConfig c = parse_pipeline_config(
      R"({"preset": "sparse-keyframes", "segmenter": {"min_points": 50}, "ground": {"method": "none"}})", "cfg");
  EXPECT_FLOAT_EQ(c.localizer.segmentation.voxel.leaf_m, 0.2f);  // from the preset
  EXPECT_EQ(c.localizer.segmentation.voxel.min_points_per_voxel, 1);
  EXPECT_EQ(c.localizer.segmentation.segmenter.min_points, 50);  // overridden
  EXPECT_EQ(c.localizer.segmentation.ground.method, GroundRemoval::kNone);
}

TEST(PipelineConfig, MistakesAreNamed) {
  EXPECT_NE(error_of("{").find("not valid JSON"), std::string::npos);
  EXPECT_NE(error_of("[1]").find("JSON object"), std::string::npos);
  EXPECT_NE(error_of(R"({"preset": "velodyne"})").find("unknown preset \"velodyne\""), std::string::npos);
  EXPECT_NE(error_of(R"({"voxels": {}})").find("unknown section \"voxels\""), std::string::npos);
  EXPECT_NE(error_of(R"({"voxel": {"leaf": 0.1}})").find("unknown key \"voxel.leaf\""), std::string::npos);
  EXPECT_NE(error_of(R"({"voxel": {"leaf_m": "big"}})").find("\"voxel.leaf_m\" must be a number"), std::string::npos);
  EXPECT_NE(error_of(R"({"retrieval": {"k": 2.5}})").find("\"retrieval.k\" must be a whole number"), std::string::npos);
  EXPECT_NE(error_of(R"({"descriptors": {"esf_seed": -1}})").find("must not be negative"), std::string::npos);
  EXPECT_NE(error_of(R"({"matcher": {"type": "svm"}})").find("l2, random_forest"), std::string::npos);
  EXPECT_NE(error_of(R"({"voxel": {"leaf_m": -1}})").find("invalid value"), std::string::npos);
  EXPECT_NE(error_of(R"({"voxel": 3})").find("\"voxel\" must be an object"), std::string::npos);
  EXPECT_EQ(error_of(R"({"voxel": {"leaf_m": 0.2}})"), "");
}

// Found by fuzzing (scripts/fuzz.sh config): a number too large for a double made nlohmann-json
// throw out_of_range, which escaped without naming the file.
TEST(PipelineConfig, NumberTooLargeForADoubleIsNamed) {
  const std::string error = error_of(R"({"voxel": {"leaf_m": 2.2e2222222222}})");
  EXPECT_NE(error.find("cfg.json: not valid JSON"), std::string::npos) << error;
  EXPECT_NE(error_of("2e99999").find("cfg.json"), std::string::npos);
}

TEST(PipelineConfig, FileErrorsNameThePath) {
  try {
    read_pipeline_config("/nonexistent/dir/cfg.json");
    FAIL() << "expected IoError";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/dir/cfg.json"), std::string::npos);
  }
  const std::string path = ::testing::TempDir() + "/pipeline_config_test.json";
  std::ofstream(path) << R"({"retrieval": {"k": 50}})";
  EXPECT_EQ(read_pipeline_config(path).localizer.retrieval.k, 50);
  std::remove(path.c_str());
}

// segmatch-mapbuilder --close-loops records what the loop closure did under "loop_closure" in
// the map's parameters: a record, not a parameter. It parses, and is not written back, so the
// parameters a server sends (io::to_json of the parsed config) stay readable by older clients.
TEST(PipelineConfig, LoopClosureRecordIsReadAndNotWrittenBack) {
  const std::string text = R"({"preset": "kitti-hdl64", "loop_closure": {"loops": [], "downweighted": 0}})";
  const segmatch::io::PipelineConfig c = segmatch::io::parse_pipeline_config(text, "test");
  EXPECT_EQ(segmatch::io::to_json(c).find("loop_closure"), std::string::npos);
}

// A map written before refine.max_segment_points existed keeps refining on every point (its
// stored answers, e.g. maps/tiny-3's goldens, hold); maps written now store the cut.
TEST(PipelineConfig, StoredMapParametersKeepTheBehaviourTheyWereBuiltWith) {
  using segmatch::io::PipelineConfig;
  const PipelineConfig today = segmatch::io::pipeline_preset("kitti-hdl64");
  EXPECT_EQ(today.localizer.refine.max_segment_points, 20000);
  EXPECT_EQ(
      segmatch::io::parse_map_parameters(segmatch::io::to_json(today), "new map").localizer.refine.max_segment_points,
      20000);
  const std::string old_map = R"({"preset": "kitti-hdl64", "refine": {"max_query_points": 2000}})";
  EXPECT_EQ(segmatch::io::parse_map_parameters(old_map, "old map").localizer.refine.max_segment_points, 0);
  // ... and answers for its whole cloud, as it did: the recent window came after it.
  EXPECT_EQ(segmatch::io::parse_map_parameters(old_map, "old map").localizer.refine.recent_window_m, 0.0f);
  EXPECT_EQ(
      segmatch::io::parse_map_parameters(segmatch::io::to_json(today), "new map").localizer.refine.recent_window_m,
      today.localizer.refine.recent_window_m);
  EXPECT_EQ(segmatch::io::parse_pipeline_config(old_map, "a config file").localizer.refine.max_segment_points, 20000)
      << "a config file that leaves it out gets today's default";
}
