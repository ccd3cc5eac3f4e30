#include "segmatch/sim/dataset.h"
#include "segmatch/sim/city.h"

#include "segmatch/io/cloud_io.h"
#include "segmatch/io/pose_io.h"
#include "segmatch/sim/render.h"

#include <nlohmann/json.hpp>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>

namespace segmatch::sim {
namespace fs = std::filesystem;
namespace {

constexpr double kRevisitM = 5.0;    // a scan of 01 this close to one of 00 revisits it
constexpr double kUnmappedM = 30.0;  // a scan of 01 this far from all of 00 is off the map

// KITTI odometry sequence 00's LiDAR-to-camera transform.
Pose3d kitti_T_cam0_velo() {
  Eigen::Matrix<double, 3, 4> m;
  m << 4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02, -7.210626507497e-03,
      8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02, 9.999738645903e-01, 4.859485810390e-04,
      -7.206933692422e-03, -2.921968648686e-01;
  Pose3d T = Pose3d::Identity();
  T.linear() = m.leftCols<3>();
  T.translation() = m.col(3);
  return T;
}

std::string frame_name(size_t i, const char* ext) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06zu%s", i, ext);
  return buf;
}

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream f(path);
  f << text;
  if (!f) throw std::runtime_error("cannot write " + path.string());
}

// poses.txt and, drifted as the keyframes' odometry (KeyframeConfig), odom_poses.txt.
void write_sequence_metadata(const fs::path& dir, const Traversal& t, const KeyframeConfig& drift) {
  fs::create_directories(dir / "velodyne");
  const Pose3d T_cam0_velo = kitti_T_cam0_velo();
  Poses relative;
  const Pose3d T_lidar0_world = t.T_world_lidar.front().inverse();
  for (const auto& T : t.T_world_lidar) relative.push_back(T_lidar0_world * T);
  io::write_kitti_poses((dir / "poses.txt").string(), io::lidar_to_camera_poses(relative, T_cam0_velo));
  io::write_kitti_poses((dir / "odom_poses.txt").string(),
                        io::lidar_to_camera_poses(drifted_odometry(relative, drift), T_cam0_velo));
  io::write_kitti_calib((dir / "calib.txt").string(), io::KittiCalib{T_cam0_velo});
  io::write_times((dir / "times.txt").string(), t.times_s);
}

void write_objects_csv(const fs::path& path, const World& w) {
  std::string text = "instance,kind,x,y,yaw,half_x,half_y,height\n";
  char line[200];
  for (const auto& o : w.objects) {
    std::snprintf(line, sizeof line, "%u,%s,%.3f,%.3f,%.4f,%.3f,%.3f,%.3f\n", o.instance, to_string(o.kind),
                  o.position.x(), o.position.y(), o.yaw, o.half_extents.x(), o.half_extents.y(), o.height_m);
    text += line;
  }
  write_text(path, text);
}

void write_revisits(const fs::path& path, const std::vector<RevisitMatch>& matches) {
  std::string text =
      "# For every scan of sequence 01: the nearest scan of sequence 00 by sensor position.\n"
      "# frame_01 frame_00 distance_m heading_diff_deg   (heading_diff ~0: same direction, ~180: opposite)\n";
  char line[128];
  for (const auto& m : matches) {
    std::snprintf(line, sizeof line, "%d %d %.3f %.1f\n", m.frame, m.reference_frame, m.distance_m, m.heading_diff_deg);
    text += line;
  }
  write_text(path, text);
}

struct SequenceJob {
  const World* world;
  const Traversal* traversal;
  int index;  // 0 or 1
};

// Simulates every scan of a sequence on `threads` workers. Each scan's noise is seeded from
// (seed, sequence, frame), so the bytes do not depend on the number of threads.
size_t simulate_sequence(const DatasetConfig& c, const SequenceJob& job, const fs::path& dir,
                         const ProgressFn& progress, SimulatedScan* keep, size_t keep_frame) {
  const LidarModel model = lidar_model_by_name(c.sensor);
  char stage[64];
  std::snprintf(stage, sizeof stage, "seq %02d: BVH", job.index);
  if (progress) progress(stage, 0, 1);
  const RayCaster caster(job.world->scene());
  if (c.write_labels) fs::create_directories(dir / "labels");
  const size_t total = job.traversal->size();
  // A rosette's frames continue one pattern along the sequence, from a seeded start within
  // its first hour.
  const double pattern_start_s =
      static_cast<double>(mix_seed(c.world.seed, 0x5ca9 + job.index, 0x7153) >> 11) * 0x1.0p-53 * 3600.0;
  std::atomic<size_t> next{0}, done{0}, points{0};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto worker = [&] {
    try {
      for (size_t i; (i = next++) < total && !error;) {
        const uint64_t seed = mix_seed(c.world.seed, 0x5ca9 + job.index, i);
        SimulatedScan scan = simulate_scan(caster, model, job.traversal->T_world_lidar[i], seed,
                                           pattern_start_s + job.traversal->times_s[i]);
        io::write_kitti_bin((dir / "velodyne" / frame_name(i, ".bin")).string(), scan.points);
        if (c.write_labels) io::write_kitti_labels((dir / "labels" / frame_name(i, ".label")).string(), scan.labels);
        points += scan.points.size();
        if (keep && i == keep_frame) *keep = std::move(scan);
        ++done;
      }
    } catch (...) {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };
  const int n = c.threads > 0 ? c.threads : std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (int k = 0; k < n; ++k) pool.emplace_back(worker);
  std::snprintf(stage, sizeof stage, "seq %02d", job.index);
  while (done < total) {
    {
      std::lock_guard<std::mutex> lock(error_mutex);
      if (error) break;
    }
    if (progress) progress(stage, done, total);
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  for (auto& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  if (progress) progress(stage, total, total);
  return points;
}

// Scans per keyframe, with 0 resolved to the sensor's default.
int keyframe_scan_count(const DatasetConfig& c) {
  return c.keyframes.frames > 0 ? c.keyframes.frames : default_keyframe_frames(lidar_model_by_name(c.sensor));
}

// Keyframes of sequence NN, made from its scans as written in sequences/NN (so they hold
// exactly the points of the KITTI layout), and their ground truth in the shared world frame.
KeyframeSummary write_sequence_keyframes(const DatasetConfig& c, int index, const Traversal& t, const fs::path& out,
                                         const ProgressFn& progress) {
  const std::string nn = index == 0 ? "00" : "01";
  const fs::path seq = out / "sequences" / nn;
  if (progress) progress("keyframes " + nn, 0, 1);
  KeyframeConfig kc = c.keyframes;
  kc.odom_seed = mix_seed(c.world.seed, static_cast<uint64_t>(index), c.keyframes.odom_seed);
  kc.frames = keyframe_scan_count(c);
  kc.write_labels = c.write_labels;
  const ScanSource read_back = [&](size_t f) {
    SimulatedScan s;
    s.points = io::read_kitti_bin((seq / "velodyne" / frame_name(f, ".bin")).string()).points;
    if (kc.write_labels) s.labels = io::read_kitti_labels((seq / "labels" / frame_name(f, ".label")).string());
    return s;
  };
  KeyframeSummary k = write_keyframes(t, read_back, kc, (out / "keyframes" / nn).string());
  io::write_kitti_poses((out / "ground_truth" / ("keyframe_poses_" + nn + ".txt")).string(), k.T_world_keyframe);
  std::string frames;
  for (size_t f : k.frames) frames += std::to_string(f) + "\n";
  write_text(out / "ground_truth" / ("keyframe_frames_" + nn + ".txt"), frames);
  if (progress) progress("keyframes " + nn, 1, 1);
  return k;
}

nlohmann::json describe(const DatasetConfig& c, const World& w, const DatasetSummary& s, const Traversal* t[2]) {
  nlohmann::json j;
  j["preset"] = c.preset;
  j["seed"] = c.world.seed;
  j["sensor"] = c.sensor;
  j["world"] = {{"blocks", {c.world.blocks_x, c.world.blocks_y}},
                {"bounds_m", {w.bounds.min().x(), w.bounds.min().y(), w.bounds.max().x(), w.bounds.max().y()}},
                {"street_length_m", s.street_length_m},
                {"primitives", s.primitives}};
  std::map<std::string, size_t> counts;
  for (const auto& o : w.objects) ++counts[to_string(o.kind)];
  j["world"]["objects"] = counts;
  for (int k = 0; k < 2; ++k) {
    const auto& T = t[k]->T_world_lidar.front();
    j["sequences"][k == 0 ? "00" : "01"] = {
        {"scans", s.scans[k]},
        {"length_m", s.length_m[k]},
        {"duration_s", t[k]->times_s.back()},
        {"T_world_lidar0_translation", {T.translation().x(), T.translation().y(), T.translation().z()}}};
  }
  const KeyframeConfig& d = c.keyframes;  // the drift of every odom_poses.txt
  j["odometry"] = {{"scale_error", d.odom_scale_error},
                   {"yaw_drift_deg_per_m", d.odom_yaw_drift_deg_per_m},
                   {"climb_m_per_m", d.odom_climb_m_per_m},
                   {"heading_walk_deg_per_sqrt_m", d.odom_heading_walk_deg_per_sqrt_m},
                   {"pitch_walk_deg_per_sqrt_m", d.odom_pitch_walk_deg_per_sqrt_m},
                   {"seed", d.odom_seed}};
  j["revisits"] = {{"frames_01_within_5m_of_00", s.revisit_frames}, {"frames_01_beyond_30m_of_00", s.unmapped_frames}};
  j["points"] = s.points;
  if (c.keyframes.every_m > 0)
    j["keyframes"] = {{"every_m", c.keyframes.every_m},
                      {"leaf_m", c.keyframes.leaf_m},
                      {"frames", keyframe_scan_count(c)},
                      {"odom_scale_error", c.keyframes.odom_scale_error},
                      {"odom_yaw_drift_deg_per_m", c.keyframes.odom_yaw_drift_deg_per_m},
                      {"count", {s.keyframes[0], s.keyframes[1]}},
                      {"points", s.keyframe_points}};
  return j;
}

}  // namespace

void DatasetConfig::use_sensor(const std::string& name) {
  const LidarModel model = lidar_model_by_name(name);
  sensor = name;
  // To the mm: 1.73f becomes exactly the 1.73 the traversals default to.
  drive_first.sensor_height_m = drive_second.sensor_height_m = std::round(model.mount_height_m * 1000.0) / 1000.0;
}

void DatasetConfig::validate() const {
  world.validate();
  keyframes.validate();
  lidar_model_by_name(sensor);  // throws on an unknown name
  if (!(first_length_m >= 50.0 && first_length_m <= 200000.0))
    throw std::invalid_argument("first traversal length must be in 50..200000 m");
  if (!(second_length_m >= 50.0 && second_length_m <= 200000.0))
    throw std::invalid_argument("second traversal length must be in 50..200000 m");
  if (first_route != "random" && first_route != "loop")
    throw std::invalid_argument("first route '" + first_route + "' is not random or loop");
  if (threads < 0 || threads > 256) throw std::invalid_argument("threads must be in 0..256");
}

std::vector<std::string> dataset_preset_names() { return {"tiny", "demo", "city"}; }

DatasetConfig dataset_preset(const std::string& name, uint64_t seed) {
  DatasetConfig c;
  c.preset = name;
  c.world.seed = seed;
  c.change.seed = seed + 1;
  c.drive_second.inner_lane = true;
  c.drive_second.lane_shift_m = 0.6;
  if (name == "tiny") {
    c.world.blocks_x = c.world.blocks_y = 2;
    c.world.block_min_m = 50;
    c.world.block_max_m = 70;
    c.first_length_m = 300;
    c.second_length_m = 160;
  } else if (name == "demo") {
    c.world.blocks_x = 4;
    c.world.blocks_y = 3;
    c.first_length_m = 1200;
    c.second_length_m = 800;
  } else if (name == "city") {
    c.world.blocks_x = 12;
    c.world.blocks_y = 10;
    c.first_length_m = 5000;
    c.second_length_m = 2500;
  } else {
    throw std::invalid_argument("unknown preset '" + name + "' (valid: tiny, demo, city)");
  }
  return c;
}

DatasetSummary generate_dataset(const DatasetConfig& c, const std::string& out_dir, const ProgressFn& progress) {
  c.validate();
  const auto start = std::chrono::steady_clock::now();
  const fs::path out(out_dir);
  fs::create_directories(out / "ground_truth");
  if (progress) progress("world", 0, 1);
  const City city = make_city(c);
  const World& world = city.world;
  const World& changed = city.changed;
  const Traversal& first = city.first;
  const Traversal& second = city.second;
  const auto revisits = match_revisits(first, second);
  if (progress) progress("world", 1, 1);

  DatasetSummary s;
  const Traversal* trav[2] = {&first, &second};
  const World* worlds[2] = {&world, &changed};
  for (int k = 0; k < 2; ++k) {
    const fs::path dir = out / "sequences" / (k == 0 ? "00" : "01");
    KeyframeConfig drift = c.keyframes;  // each sequence's odometry wanders its own way
    drift.odom_seed = mix_seed(c.world.seed, static_cast<uint64_t>(k), c.keyframes.odom_seed);
    write_sequence_metadata(dir, *trav[k], drift);
    io::write_kitti_poses((out / "ground_truth" / (k == 0 ? "lidar_poses_00.txt" : "lidar_poses_01.txt")).string(),
                          trav[k]->T_world_lidar);
    write_objects_csv(out / "ground_truth" / (k == 0 ? "objects_00.csv" : "objects_01.csv"), *worlds[k]);
    s.scans[k] = trav[k]->size();
    s.length_m[k] = trav[k]->length_m();
  }
  write_revisits(out / "ground_truth" / "revisits_01_00.txt", revisits);
  for (const auto& m : revisits) {
    s.revisit_frames += m.distance_m <= kRevisitM;
    s.unmapped_frames += m.distance_m > kUnmappedM;
  }
  s.objects = world.objects.size();
  s.primitives = world.scene().size();
  s.street_length_m = world.streets.total_length_m();

  SimulatedScan shown;
  const size_t shown_frame = second.size() / 2;
  for (int k = 0; k < 2; ++k) {
    const fs::path dir = out / "sequences" / (k == 0 ? "00" : "01");
    s.points += simulate_sequence(c, {worlds[k], trav[k], k}, dir, progress, k == 1 ? &shown : nullptr, shown_frame);
    if (c.keyframes.every_m > 0) {
      const KeyframeSummary kf = write_sequence_keyframes(c, k, *trav[k], out, progress);
      s.keyframes[k] = kf.frames.size();
      s.keyframe_points += kf.points;
    }
  }
  if (c.write_images) {
    write_world_png((out / "world.png").string(), world, &changed, first, &second);
    write_scan_png((out / "scan.png").string(), shown, lidar_model_by_name(c.sensor),
                   "sequence 01, scan " + std::to_string(shown_frame) + ", " + c.sensor + ", " +
                       std::to_string(shown.points.size()) + " points");
  }
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  write_text(out / "dataset.json", describe(c, world, s, trav).dump(2) + "\n");
  return s;
}

}  // namespace segmatch::sim
