#include "segmatch/sim/city.h"

#include <iterator>

namespace segmatch::sim {

City make_city(const DatasetConfig& c) {
  City city;
  city.world = generate_world(c.world);
  city.changed = change_world(city.world, c.change);
  Rng rng(mix_seed(c.world.seed, 0x7a5e));
  const Route first = plan_route(city.world.streets, c.first_length_m, rng);
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
  for_each_local_cloud(caster, model, traversal, config.local_cloud, config.schedule,
                       [&](const SimulatedLocalCloud& lc) {
                         Segments s = extract_segments(lc.cloud, lc.T_world_sensor.translation().cast<float>(),
                                                       config.segmentation, &lc.labels);
                         if (config.merge) map.add(std::move(s));
                         else std::move(s.begin(), s.end(), std::back_inserter(all));
                       });
  return config.merge ? map.segments() : all;
}

}  // namespace segmatch::sim
