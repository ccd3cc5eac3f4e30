// The auto profile: the pipeline derived from measurements, its JSON form (what a map stores)
// and the loop settings it brings.
#include "segmatch/io/auto_profile.h"
#include "segmatch/io/error.h"
#include "segmatch/io/pipeline_config.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

using namespace segmatch;
using namespace segmatch::io;

namespace {

InputMeasurements measured(bool wide, bool downsampled) {
  InputMeasurements m;
  m.scans_measured = 24;
  m.points_per_scan = wide ? 12000 : 5000;
  m.azimuth_coverage = wide ? 0.9 : 0.2;
  m.elevation_min_deg = -15, m.elevation_max_deg = 15;
  m.range_p50_m = wide ? 12.0 : 10.3;
  m.range_p95_m = wide ? 38.0 : 22.0;
  m.spacing_p10_m = downsampled ? 0.1 : 0.02;
  m.spacing_p50_m = downsampled ? 0.19 : 0.09;
  m.spacing_per_range = 0.01;
  m.scan_distance_m = wide ? 6.0 : 0.35;
  m.downsampled = downsampled;
  m.wide_fov = wide;
  return m;
}

}  // namespace

TEST(AutoProfile, DenseSpinningIsThePapersPreset) {
  const PipelineConfig a = auto_pipeline_config(measured(true, false));
  PipelineConfig k = pipeline_preset("kitti-hdl64");
  k.preset = "auto";
  k.measured = a.measured;
  EXPECT_EQ(to_json(a), to_json(k));
}

TEST(AutoProfile, SparseSpinningTakesTheMeasuredSpacing) {
  const PipelineConfig c = auto_pipeline_config(measured(true, true));
  const SegmentationConfig& s = c.localizer.segmentation;
  EXPECT_FLOAT_EQ(s.voxel.leaf_m, 0.2f);
  EXPECT_EQ(s.voxel.min_points_per_voxel, 1);
  EXPECT_FLOAT_EQ(s.segmenter.cluster_distance_m, 0.4f);
  EXPECT_EQ(s.segmenter.min_points, 30);
  EXPECT_DOUBLE_EQ(c.local_cloud.min_travel_between_scans_m, 0.0);  // keyframes 6 m apart
  EXPECT_EQ(c.localizer.matcher.type, MatcherType::kRandomForest);
  InputMeasurements coarser = measured(true, true);
  coarser.spacing_p50_m = 0.31;
  EXPECT_FLOAT_EQ(auto_pipeline_config(coarser).localizer.segmentation.voxel.leaf_m, 0.3f);
}

TEST(AutoProfile, NarrowFovGetsACylinderFromItsRangeAndLoopSettingsThatGrowWithDistance) {
  const PipelineConfig c = auto_pipeline_config(measured(false, false));
  EXPECT_DOUBLE_EQ(c.local_cloud.radius_m, 30.0);  // 3 x 10.3 m, to 5 m
  EXPECT_EQ(c.localizer.matcher.type, MatcherType::kL2);
  const LoopDetectorConfig l = loop_detector_config(c);
  EXPECT_DOUBLE_EQ(l.exclude_recent_distance_m, 26.0);
  EXPECT_DOUBLE_EQ(l.drift_bound_m(0.0), 0.5);
  EXPECT_DOUBLE_EQ(l.drift_bound_m(100.0), 1.5);
  EXPECT_NO_THROW(l.validate());
  // A spinning sensor keeps the detector's defaults (no drift bound).
  EXPECT_DOUBLE_EQ(loop_detector_config(auto_pipeline_config(measured(true, true))).drift_bound_m(100.0), 0.0);
}

TEST(AutoProfile, MeasurementsRoundTripThroughJson) {
  const PipelineConfig c = auto_pipeline_config(measured(false, false));
  const std::string text = to_json(c);
  const PipelineConfig back = parse_pipeline_config(text, "map parameters");
  ASSERT_TRUE(back.measured.has_value());
  EXPECT_EQ(back.measured->sensor_class(), "narrow-fov");
  EXPECT_DOUBLE_EQ(back.measured->range_p50_m, 10.3);
  EXPECT_EQ(to_json(back), text);
  EXPECT_EQ(back.preset, "auto");
}

// The beam layout round-trips; maps measured before it (no ring keys) still parse, with no
// rings, and a missing older key is still refused by name.
TEST(AutoProfile, RingsRoundTripAndOlderMapsParseWithout) {
  InputMeasurements m = measured(true, false);
  m.ring_count = 32;
  m.ring_spacing_deg = 1.33;
  PipelineConfig c = auto_pipeline_config(m);
  const PipelineConfig back = parse_pipeline_config(to_json(c), "map parameters");
  ASSERT_TRUE(back.measured.has_value());
  EXPECT_DOUBLE_EQ(back.measured->ring_count, 32.0);
  EXPECT_DOUBLE_EQ(back.measured->ring_spacing_deg, 1.33);
  EXPECT_EQ(back.measured->beam_layout(), "32-beam spinning");
  nlohmann::json older = nlohmann::json::parse(to_json(c));
  older["measured"].erase("ring_count");
  older["measured"].erase("ring_spacing_deg");
  const PipelineConfig old_map = parse_pipeline_config(older.dump(), "schema-4 map");
  ASSERT_TRUE(old_map.measured.has_value());
  EXPECT_EQ(old_map.measured->ring_count, 0.0);
  EXPECT_EQ(old_map.measured->beam_layout(), "spinning, rings not resolved");
  older["measured"].erase("range_p50_m");
  try {
    parse_pipeline_config(older.dump(), "cfg.json");
    FAIL() << "accepted";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("measured.range_p50_m\" is missing"), std::string::npos) << e.what();
  }
}

// The elevations the map's sensor saw follow from its measurements, in the map builder's config
// and in a map's parameters read back (a cold start keeps another sensor's scan to them); a
// config without measurements leaves them open.
TEST(AutoProfile, TheMeasuredElevationsBoundAColdStartsScan) {
  InputMeasurements m = measured(true, false);
  m.elevation_min_deg = -24.9;
  m.elevation_max_deg = 2.0;
  const PipelineConfig c = auto_pipeline_config(m);
  EXPECT_FLOAT_EQ(c.localizer.places.map_elevation_min_deg, -24.9f);
  EXPECT_FLOAT_EQ(c.localizer.places.map_elevation_max_deg, 2.0f);
  const PipelineConfig back = parse_pipeline_config(to_json(c), "map parameters");
  EXPECT_FLOAT_EQ(back.localizer.places.map_elevation_min_deg, -24.9f);
  EXPECT_FLOAT_EQ(back.localizer.places.map_elevation_max_deg, 2.0f);
  const PipelineConfig open = parse_pipeline_config(R"({"preset": "kitti-hdl64"})", "cfg.json");
  EXPECT_FLOAT_EQ(open.localizer.places.map_elevation_min_deg, -90.0f);
  EXPECT_FLOAT_EQ(open.localizer.places.map_elevation_max_deg, 90.0f);
}

TEST(AutoProfile, BadMeasurementsAreNamed) {
  try {
    parse_pipeline_config(R"({"preset": "auto", "measured": {"range_p50_m": "far"}})", "cfg.json");
    FAIL() << "accepted";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("measured."), std::string::npos) << e.what();
  }
  EXPECT_THROW(parse_pipeline_config(R"({"measured": 3})", "cfg.json"), IoError);
}
