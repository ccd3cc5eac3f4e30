#include "segmatch/sim/city.h"

#include <iterator>

namespace segmatch::sim {

City make_city(const DatasetConfig& c) {
  City city;
  city.world = generate_world(c.world);
  city.changed = change_world(city.world, c.change);
  Rng rng(mix_seed(c.world.seed, 0x7a5e));
  const Route first = c.first_route == "loop" ? plan_loop_route(city.world.streets, 3)
                                              : plan_route(city.world.streets, c.first_length_m, rng);
  const Route second = plan_revisit_route(city.world.streets, first, c.second_length_m, rng);
  city.first = drive(city.world, first, c.drive_first);
  city.second = drive(city.changed, second, c.drive_second);
  return city;
}

Segments segments_along(const World& world, const Traversal& traversal, const LidarModel& model,
                        const SegmentsAlongConfig& config) {
  const RayCaster caster(world.scene());
  SegmentMap map(config.segment_map);
  Segments all;
  for_each_voxelized_cloud(caster, model, traversal, without_age_limit(config.local_cloud), config.segmentation.voxel,
                           config.schedule, [&](const SimulatedLocalCloud& lc) {
                             Segments s =
                                 extract_segments_from_voxels(lc.cloud, lc.T_world_sensor.translation().cast<float>(),
                                                              config.segmentation, &lc.labels);
                             if (config.merge)
                               map.add(std::move(s));
                             else
                               std::move(s.begin(), s.end(), std::back_inserter(all));
                           });
  return config.merge ? map.segments() : all;
}

std::unique_ptr<LabelledCity> labelled_city(const DatasetConfig& dataset, const LidarModel& model,
                                            SegmentsAlongConfig along, const TrainingPairConfig& pair_config) {
  const City city = make_city(dataset);
  const uint64_t seed = dataset.world.seed;
  auto out = std::make_unique<LabelledCity>();
  along.merge = true;
  along.schedule.every_m = 5.0;
  along.schedule.seed = mix_seed(seed, 1);
  out->targets = segments_along(city.world, city.first, model, along);
  along.merge = false;
  along.schedule.every_m = 10.0;
  along.schedule.seed = mix_seed(seed, 2);
  out->queries = segments_along(city.changed, city.second, model, along);
  FeatureIndex index;
  index.build(out->targets);
  out->pairs = label_pairs_by_instance(out->queries, out->targets, index, pair_config);
  return out;
}

}  // namespace segmatch::sim
