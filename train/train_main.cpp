// segmatch-train: labelled segment pairs from simulated cities (exact instance ids), then the
// random forest of the paper (section III-D, IV-B), saved as a model file.
//
// For every city: the map is the merged segments of the mapping traversal (one local cloud
// every 5 m), the queries are the unmerged segments of the revisit (every 10 m, changed
// world, other lane). Each query segment's k nearest map segments in feature space are its
// candidate pairs; same instance = positive; negatives are kept at 1:50 (paper IV-B).
#include "segmatch/cli/progress.h"
#include "segmatch/core/training.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/sim/city.h"

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

std::unique_ptr<sim::LabelledCity> city_pairs(const std::string& preset, uint64_t seed, const io::PipelineConfig& config,
                                              const std::string& sensor) {
  sim::SegmentsAlongConfig along;
  along.local_cloud = config.local_cloud;
  along.segmentation = config.localizer.segmentation;
  along.segment_map = config.segment_map;
  TrainingPairConfig pc;
  pc.k = config.localizer.retrieval.k;
  pc.seed = seed;
  return sim::labelled_city(sim::dataset_preset(preset, seed), sim::lidar_model_by_name(sensor), along, pc);
}

void write_atomically(const std::string& path, const std::string& bytes) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (!f) throw std::runtime_error(tmp + ": cannot open for writing");
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!f.flush()) throw std::runtime_error(tmp + ": write failed");
  }
  fs::rename(tmp, path);
}

// True and false positive rates of the model on held-out pairs at its threshold.
void report_holdout(const RandomForestMatcher& rf, const TrainingPairs& p) {
  size_t tp = 0, fp = 0;
  const float threshold = rf.config().rf_threshold;
  for (size_t i = 0; i < p.pairs.size(); ++i) {
    const bool accepted = rf.probability(*p.pairs[i].first, *p.pairs[i].second) >= threshold;
    (p.same_object[i] ? tp : fp) += accepted;
  }
  std::printf("held-out city: %zu positives, %zu negatives; at threshold %.2f: TPR %.3f, FPR %.4f\n", p.positives,
              p.negatives, threshold, p.positives ? double(tp) / p.positives : 0.0,
              p.negatives ? double(fp) / p.negatives : 0.0);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Train the SegMatch segment-match random forest on simulated cities"};
  std::string out, config_path, preset = "tiny", sensor = "hdl64e";
  std::vector<uint64_t> seeds = {101, 102, 103, 105, 106};
  uint64_t holdout = 104;
  bool eigen_only = false;
  std::string eigen_out;
  app.add_option("-o,--out", out, "model file to write (e.g. maps/models/default-rf.yml)")->required();
  app.add_option("--config", config_path, "pipeline config JSON (default: the kitti-hdl64 preset)");
  app.add_option("--preset", preset, "simulated city size: tiny, demo, city")->check(CLI::IsMember(sim::dataset_preset_names()));
  app.add_option("--seeds", seeds, "city seeds to train on")->delimiter(',');
  app.add_option("--holdout-seed", holdout, "city seed to report TPR / FPR on (0: none)");
  app.add_option("--sensor", sensor, "hdl64e, vlp16, os1-64");
  app.add_flag("--eigen-only", eigen_only, "train RF_eigen (21 pair features) instead of RF_eigen+shapes (31)");
  app.add_option("--eigen-out", eigen_out, "also train RF_eigen on the same pairs and write it here");
  CLI11_PARSE(app, argc, argv);
  try {
    io::PipelineConfig config = config_path.empty() ? io::pipeline_preset("kitti-hdl64") : io::read_pipeline_config(config_path);
    config.localizer.matcher.use_shapes = !eigen_only;
    if (eigen_only) config.localizer.matcher.rf_threshold = 0.81f;  // paper Table I
    config.validate();
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::unique_ptr<sim::LabelledCity>> cities;
    std::vector<std::pair<const Segment*, const Segment*>> pairs;
    std::vector<bool> same;
    cli::Progress progress("cities", seeds.size(), "cities");
    for (uint64_t seed : seeds) {
      cities.push_back(city_pairs(preset, seed, config, sensor));
      const TrainingPairs& p = cities.back()->pairs;
      pairs.insert(pairs.end(), p.pairs.begin(), p.pairs.end());
      same.insert(same.end(), p.same_object.begin(), p.same_object.end());
      progress.advance();
    }
    progress.finish();
    RandomForestMatcher rf(config.localizer.matcher);
    rf.train(pairs, same);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    size_t positives = 0;
    for (bool s : same) positives += s;
    std::printf("trained %s on %zu cities: %zu positives, %zu negatives, %.0f s\n",
                eigen_only ? "RF_eigen" : "RF_eigen+shapes", seeds.size(), positives, pairs.size() - positives, seconds);
    write_atomically(out, rf.save());
    std::printf("model written to %s\n", out.c_str());
    std::unique_ptr<RandomForestMatcher> rf_eigen;
    if (!eigen_out.empty() && !eigen_only) {
      MatcherConfig mc = config.localizer.matcher;
      mc.use_shapes = false;
      mc.rf_threshold = 0.81f;  // paper Table I
      rf_eigen = std::make_unique<RandomForestMatcher>(mc);
      rf_eigen->train(pairs, same);
      write_atomically(eigen_out, rf_eigen->save());
      std::printf("RF_eigen model written to %s\n", eigen_out.c_str());
    }
    if (holdout != 0) {
      const auto held_out = city_pairs(preset, holdout, config, sensor);
      report_holdout(rf, held_out->pairs);
      if (rf_eigen) report_holdout(*rf_eigen, held_out->pairs);
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-train: %s\n", e.what());
    return 1;
  }
}
