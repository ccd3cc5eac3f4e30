#include "segmatch/eval/real_pairs.h"

#include "segmatch/cli/progress.h"
#include "segmatch/core/mapping/map_builder.h"
#include "segmatch/core/preprocess/voxel_accumulator.h"
#include "segmatch/io/sequence.h"

#include <vector>

namespace segmatch::eval {
namespace {

// Distance driven at each keyframe (sum of the steps between consecutive poses).
std::vector<double> odometer(const io::Sequence& seq) {
  std::vector<double> at(seq.size(), 0.0);
  for (size_t i = 1; i < seq.size(); ++i)
    at[i] = at[i - 1] + (seq.poses()[i].translation() - seq.poses()[i - 1].translation()).norm();
  return at;
}

// The map side: even keyframes through MapBuilder (world frame, duplicates merged).
Segments map_segments(const io::Sequence& seq, const io::PipelineConfig& config, double every_m,
                      std::vector<double>& odometer_of_segment, const std::vector<double>& odo) {
  MapBuilderConfig mc;
  mc.local_cloud = config.local_cloud;
  mc.segmentation = config.localizer.segmentation;
  mc.segment_map = config.segment_map;
  mc.map_every_m = every_m;
  MapBuilder builder(mc);
  cli::Progress progress("map side (even keyframes)", (seq.size() + 1) / 2, "keyframes");
  for (size_t i = 0; i < seq.size(); i += 2) {
    builder.add_scan(seq.scan(i).points, seq.poses()[i], static_cast<uint32_t>(i));
    progress.advance();
  }
  builder.finish();
  progress.finish();
  for (uint32_t k : builder.keyframe_of_segment()) odometer_of_segment.push_back(odo[k]);
  return builder.segments();
}

// The query side: odd keyframes, a local cloud every `every_m`, its segments unmerged.
Segments query_segments(const io::Sequence& seq, const io::PipelineConfig& config, const RealPairsConfig& rc,
                        std::vector<double>& odometer_of_segment, const std::vector<double>& odo) {
  VoxelAccumulator local(config.local_cloud, config.localizer.segmentation.voxel);
  Segments out;
  double last_m = -1e18;
  cli::Progress progress("query side (odd keyframes)", seq.size() / 2, "keyframes");
  for (size_t i = 1; i < seq.size(); i += 2) {
    const Pose3d& T_world_sensor = seq.poses()[i];
    local.add_scan(seq.scan(i).points, T_world_sensor);
    progress.advance();
    if (odo[i] - odo[1] < rc.warmup_m || odo[i] - last_m < rc.query_every_m) continue;
    last_m = odo[i];
    Segments s = extract_segments_from_voxels(local.crop(T_world_sensor), T_world_sensor.translation().cast<float>(),
                                              config.localizer.segmentation);
    for (Segment& seg : s) {
      odometer_of_segment.push_back(odo[i]);
      out.push_back(std::move(seg));
    }
  }
  progress.finish();
  return out;
}

// Moves each segment to `train` or `held_out` by the stretch of the drive it was seen from.
void split(Segments& all, const std::vector<double>& odo, const RealPairsConfig& rc, Segments& train,
           Segments& held_out) {
  for (size_t i = 0; i < all.size(); ++i) {
    const long block = static_cast<long>(odo[i] / rc.block_m);
    (block % rc.held_out_every == rc.held_out_every - 1 ? held_out : train).push_back(std::move(all[i]));
  }
  all.clear();
}

}  // namespace

std::unique_ptr<RealPairs> real_pairs(const std::string& folder, const io::PipelineConfig& config,
                                      const RealPairsConfig& rc) {
  if (!(rc.block_m > 0.0)) throw std::invalid_argument("block_m must be > 0");
  if (rc.held_out_every < 2) throw std::invalid_argument("held_out_every must be >= 2");
  const io::Sequence seq = io::Sequence::open(folder);
  if (seq.size() < 4) throw std::invalid_argument(folder + ": fewer than 4 keyframes");
  const std::vector<double> odo = odometer(seq);
  auto out = std::make_unique<RealPairs>();
  out->drive_m = odo.back();
  std::vector<double> target_odo, query_odo;
  Segments targets = map_segments(seq, config, rc.map_every_m, target_odo, odo);
  Segments queries = query_segments(seq, config, rc, query_odo, odo);
  split(targets, target_odo, rc, out->targets_train, out->targets_held_out);
  split(queries, query_odo, rc, out->queries_train, out->queries_held_out);
  // Each half is labelled against the map of its own stretch only: no held-out target is
  // seen in training, not even as a negative.
  FeatureIndex train_index, held_out_index;
  train_index.build(out->targets_train);
  held_out_index.build(out->targets_held_out);
  out->train = label_pairs_by_distance(out->queries_train, out->targets_train, train_index, rc.pairs);
  out->held_out = label_pairs_by_distance(out->queries_held_out, out->targets_held_out, held_out_index, rc.pairs);
  return out;
}

}  // namespace segmatch::eval
