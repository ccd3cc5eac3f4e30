// segmatch-train: labelled segment pairs from simulated cities (exact instance ids) or from a
// real recording (--real: labels by centroid distance under its poses, real_pairs.h), then the
// random forest of the paper (section III-D, IV-B), saved as a model file.
//
// For every city: the map is the merged segments of the mapping traversal (one local cloud
// every 5 m), the queries are the unmerged segments of the revisit (every 10 m, changed
// world, other lane). Each query segment's k nearest map segments in feature space are its
// candidate pairs; same instance = positive; negatives are kept at 1:50 (paper IV-B).
#include "segmatch/cli/progress.h"
#include "segmatch/core/training/training.h"
#include "segmatch/eval/real_pairs.h"
#include "segmatch/io/auto_profile.h"
#include "segmatch/io/error.h"
#include "segmatch/io/pipeline_config.h"
#include "segmatch/sim/city.h"

#include <segmatch/cli/tool.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>

using namespace segmatch;
namespace fs = std::filesystem;

namespace {

std::unique_ptr<sim::LabelledCity> city_pairs(const std::string& preset, uint64_t seed,
                                              const io::PipelineConfig& config, const std::string& sensor) {
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

RandomForestMatcher load_model(const std::string& path) {
  return RandomForestMatcher::load(io::read_file_bytes(path, "model file"));
}

// True and false positive rates of the model on held-out pairs at its threshold.
// Area under the ROC curve: the probability that a random positive scores above a random
// negative (ties count half), by ranks.
double roc_auc(const std::vector<float>& score, const std::vector<bool>& positive) {
  std::vector<size_t> order(score.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return score[a] < score[b]; });
  double rank_sum = 0.0, positives = 0.0;
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    while (j < order.size() && score[order[j]] == score[order[i]]) ++j;
    const double mid_rank = 0.5 * static_cast<double>(i + j + 1);  // ranks are 1-based
    for (size_t k = i; k < j; ++k)
      if (positive[order[k]]) rank_sum += mid_rank, positives += 1.0;
    i = j;
  }
  const double negatives = static_cast<double>(score.size()) - positives;
  if (positives == 0.0 || negatives == 0.0) return 0.0;
  return (rank_sum - positives * (positives + 1.0) / 2.0) / (positives * negatives);
}

// AUC, and true and false positive rates at the model's threshold, on held-out pairs.
void report_holdout(const std::string& name, const RandomForestMatcher& rf, const TrainingPairs& p) {
  size_t tp = 0, fp = 0;
  const float threshold = rf.config().rf_threshold;
  std::vector<float> score(p.pairs.size());
  for (size_t i = 0; i < p.pairs.size(); ++i) {
    score[i] = rf.probability(*p.pairs[i].first, *p.pairs[i].second);
    (p.same_object[i] ? tp : fp) += score[i] >= threshold;
  }
  std::printf("%s: held out %zu positives, %zu negatives: AUC %.3f; at threshold %.2f: TPR %.3f, FPR %.4f\n",
              name.c_str(), p.positives, p.negatives, roc_auc(score, p.same_object), threshold,
              p.positives ? double(tp) / p.positives : 0.0, p.negatives ? double(fp) / p.negatives : 0.0);
}

struct TrainOptions {
  std::string out, config_path, preset = "tiny", sensor = "hdl64e";
  std::vector<uint64_t> seeds = {101, 102, 103, 105, 106};
  uint64_t holdout = 104;
  bool eigen_only = false;
  std::string eigen_out, real_dir;
  std::vector<std::string> baselines;
};

void add_options(CLI::App& app, TrainOptions& o) {
  cli::add_output_option(app, o.out, "model file to write (e.g. maps/models/default-rf.yml), required");
  app.add_option("--config", o.config_path, "pipeline config JSON (default: the kitti-hdl64 preset)");
  app.add_option("--preset", o.preset, "simulated city size: tiny, demo, city")
      ->check(CLI::IsMember(sim::dataset_preset_names()));
  app.add_option("--seeds", o.seeds, "city seeds to train on")->delimiter(',');
  app.add_option("--holdout-seed", o.holdout, "city seed to report TPR / FPR on (0: none)");
  app.add_option("--sensor", o.sensor, "hdl64e, vlp16, os1-64");
  app.add_flag("--eigen-only", o.eigen_only, "train RF_eigen (21 pair features) instead of RF_eigen+shapes (31)");
  app.add_option("--eigen-out", o.eigen_out, "also train RF_eigen on the same pairs and write it here");
  app.add_option(
      "--real", o.real_dir,
      "train on a real keyframe folder instead (e.g. ../shared/data/real/riverside02): map side from the even "
      "keyframes, queries from the odd ones, labels by centroid distance; every 3rd 300 m stretch of the drive "
      "is held out (default config: the auto profile measured from that folder)");
  app.add_option("--baseline", o.baselines, "also report these existing model files on the same held-out pairs");
}

// Default: the auto profile. Simulated HDL-64E scans measure as dense-spinning, i.e. the
// kitti-hdl64 values, so only a real folder is measured.
io::PipelineConfig training_config(const TrainOptions& o) {
  io::PipelineConfig config = !o.config_path.empty() ? io::read_pipeline_config(o.config_path)
                              : o.real_dir.empty()
                                  ? io::pipeline_preset("kitti-hdl64")
                                  : io::auto_pipeline_config(io::measure_sequence(io::Sequence::open(o.real_dir)));
  if (config.measured) std::printf("%s\n", io::describe_profile(config).c_str());
  config.localizer.matcher.use_shapes = !o.eigen_only;
  if (o.eigen_only) config.localizer.matcher.rf_threshold = 0.81f;  // paper Table I
  config.validate();
  return config;
}

// The held-out pairs (the real drive's held-out stretches, or the hold-out city) scored by the
// new model(s) and the baselines.
void report_held_out(const TrainOptions& o, const io::PipelineConfig& config, const eval::RealPairs* real,
                     const RandomForestMatcher& rf, const RandomForestMatcher* rf_eigen) {
  std::unique_ptr<sim::LabelledCity> held_out_city;
  const TrainingPairs* held_out = nullptr;
  if (real) {
    std::printf("held out: every 3rd 300 m stretch of the drive\n");
    held_out = &real->held_out;
  } else if (o.holdout != 0) {
    held_out_city = city_pairs(o.preset, o.holdout, config, o.sensor);
    held_out = &held_out_city->pairs;
  }
  if (!held_out) return;
  report_holdout("new", rf, *held_out);
  if (rf_eigen) report_holdout("new RF_eigen", *rf_eigen, *held_out);
  for (const std::string& path : o.baselines) report_holdout(path, load_model(path), *held_out);
}

int train(TrainOptions o) {
  const io::PipelineConfig config = training_config(o);
  const auto start = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<sim::LabelledCity>> cities;
  std::unique_ptr<eval::RealPairs> real;
  std::vector<std::pair<const Segment*, const Segment*>> pairs;
  std::vector<bool> same;
  if (!o.real_dir.empty()) {
    eval::RealPairsConfig rc;
    rc.pairs.k = config.localizer.retrieval.k;
    real = eval::real_pairs(o.real_dir, config, rc);
    pairs = real->train.pairs;
    same = real->train.same_object;
    std::printf("real drive %.0f m: training stretch %zu map / %zu query segments, held out %zu / %zu\n", real->drive_m,
                real->targets_train.size(), real->queries_train.size(), real->targets_held_out.size(),
                real->queries_held_out.size());
    o.seeds.clear();
  }
  if (!o.seeds.empty()) {
    cli::Progress progress("cities", o.seeds.size(), "cities");
    for (uint64_t seed : o.seeds) {
      cities.push_back(city_pairs(o.preset, seed, config, o.sensor));
      const TrainingPairs& p = cities.back()->pairs;
      pairs.insert(pairs.end(), p.pairs.begin(), p.pairs.end());
      same.insert(same.end(), p.same_object.begin(), p.same_object.end());
      progress.advance();
    }
    progress.finish();
  }
  RandomForestMatcher rf(config.localizer.matcher);
  rf.train(pairs, same);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  size_t positives = 0;
  for (bool s : same) positives += s;
  std::printf("trained %s on %s: %zu positives, %zu negatives, %.0f s\n", o.eigen_only ? "RF_eigen" : "RF_eigen+shapes",
              real ? o.real_dir.c_str() : (std::to_string(o.seeds.size()) + " cities").c_str(), positives,
              pairs.size() - positives, seconds);
  write_atomically(o.out, rf.save());
  std::printf("model written to %s\n", o.out.c_str());
  std::unique_ptr<RandomForestMatcher> rf_eigen;
  if (!o.eigen_out.empty() && !o.eigen_only) {
    MatcherConfig mc = config.localizer.matcher;
    mc.use_shapes = false;
    mc.rf_threshold = 0.81f;  // paper Table I
    rf_eigen = std::make_unique<RandomForestMatcher>(mc);
    rf_eigen->train(pairs, same);
    write_atomically(o.eigen_out, rf_eigen->save());
    std::printf("RF_eigen model written to %s\n", o.eigen_out.c_str());
  }
  report_held_out(o, config, real.get(), rf, rf_eigen.get());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Train the SegMatch segment-match random forest on simulated cities"};
  TrainOptions o;
  add_options(app, o);
  cli::add_version_flag(app, "segmatch-train");
  SEGMATCH_CLI_PARSE(app, argc, argv);
  if (const int status = cli::require_output("segmatch-train", o.out); status >= 0) return status;
  try {
    return train(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "segmatch-train: %s\n", e.what());
    return 1;
  }
}
