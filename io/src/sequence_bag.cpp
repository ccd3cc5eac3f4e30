// A ROS 2 bag as a Sequence (BagOptions): one scan per PointCloud2 message, its pose
// interpolated at the cloud's header stamp from an Odometry or PoseStamped topic, from /tf and
// /tf_static, or from a TUM file matched by time.
#include <segmatch/io/bag.h>
#include <segmatch/io/pose_io.h>
#include <segmatch/io/sequence.h>

#include <algorithm>
#include <functional>
#include <map>
#include <optional>

#include "io_util.h"

namespace segmatch {
namespace io {

namespace {

constexpr const char* kPointCloud2 = "sensor_msgs/msg/PointCloud2";
constexpr const char* kOdometry = "nav_msgs/msg/Odometry";
constexpr const char* kPoseStamped = "geometry_msgs/msg/PoseStamped";
constexpr const char* kTf = "tf2_msgs/msg/TFMessage";
// A cloud stamped this close outside the poses' span takes the end pose (clock rounding).
constexpr double kSpanToleranceS = 1e-3;

// Stamped poses of one frame, sorted by time, interpolated between neighbours.
struct Track {
  std::vector<double> t;
  Poses T;
  void add(double stamp, const Pose3d& pose) {
    t.push_back(stamp);
    T.push_back(pose);
  }
  void sort() {
    std::vector<size_t> order(t.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return t[a] < t[b]; });
    Track sorted;
    for (size_t i : order) sorted.add(t[i], T[i]);
    *this = std::move(sorted);
  }
  std::optional<Pose3d> at(double stamp) const {
    if (t.empty() || stamp < t.front() - kSpanToleranceS || stamp > t.back() + kSpanToleranceS) return std::nullopt;
    const size_t hi = static_cast<size_t>(std::lower_bound(t.begin(), t.end(), stamp) - t.begin());
    if (hi == 0) return T.front();
    if (hi == t.size()) return T.back();
    const size_t lo = hi - 1;
    const double span = t[hi] - t[lo];
    const double w = span > 0.0 ? (stamp - t[lo]) / span : 0.0;
    const Eigen::Quaterniond q = Eigen::Quaterniond(T[lo].linear()).slerp(w, Eigen::Quaterniond(T[hi].linear()));
    Pose3d p = Pose3d::Identity();
    p.linear() = q.normalized().toRotationMatrix();
    p.translation() = (1.0 - w) * T[lo].translation() + w * T[hi].translation();
    return p;
  }
};

// The transform tree of /tf and /tf_static: each child frame's parent and its pose in it.
struct TfEdge {
  std::string parent;
  bool fixed = false;
  Pose3d T_parent_child = Pose3d::Identity();  // fixed
  Track track;                                 // dynamic
};
using TfTree = std::map<std::string, TfEdge>;

void add_transforms(const BagReader& bag, const std::string& topic, bool fixed, TfTree& tree) {
  for (const BagMessageRef& ref : bag.messages(topic))
    for (const StampedPose& tf : decode_tf_message(bag.data(ref))) {
      TfEdge& e = tree[tf.child_frame_id];
      e.parent = tf.header.frame_id;
      e.fixed = fixed;
      if (fixed)
        e.T_parent_child = tf.T_parent_child;
      else
        e.track.add(tf.header.stamp_s(), tf.T_parent_child);
    }
}

// T_root_frame at stamp, walking up to the root (which *root names); nullopt when a dynamic
// edge on the way has no pose at the stamp.
std::optional<Pose3d> to_root(const TfTree& tree, std::string frame, double stamp, std::string* root) {
  Pose3d T = Pose3d::Identity();
  for (size_t depth = 0; depth < 64; ++depth) {
    const auto it = tree.find(frame);
    if (it == tree.end()) {
      *root = frame;
      return T;
    }
    const TfEdge& e = it->second;
    const std::optional<Pose3d> step = e.fixed ? std::optional<Pose3d>(e.T_parent_child) : e.track.at(stamp);
    if (!step) return std::nullopt;
    T = *step * T;
    frame = e.parent;
  }
  throw IoError("/tf: the transform tree has a cycle through frame '" + frame + "'");
}

std::vector<std::string> topics_of_type(const BagReader& bag, std::initializer_list<const char*> types) {
  std::vector<std::string> names;
  for (const BagTopic& t : bag.topics())
    for (const char* type : types)
      if (t.type == type) names.push_back(t.name);
  return names;
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s.empty() ? "none" : s;
}

const BagTopic& topic_named(const BagReader& bag, const std::string& name, const std::string& flag) {
  for (const BagTopic& t : bag.topics())
    if (t.name == name) return t;
  std::vector<std::string> all;
  for (const BagTopic& t : bag.topics()) all.push_back(t.name + " (" + t.type + ")");
  throw IoError(bag.path() + ": no topic " + name + " (" + flag + "); the bag has " + joined(all));
}

std::string points_topic(const BagReader& bag, const BagOptions& o) {
  if (!o.points_topic.empty()) {
    const BagTopic& t = topic_named(bag, o.points_topic, "--points-topic");
    if (t.type != kPointCloud2) throw IoError(bag.path() + ": " + t.name + " is " + t.type + ", not " + kPointCloud2);
    return t.name;
  }
  const std::vector<std::string> clouds = topics_of_type(bag, {kPointCloud2});
  if (clouds.size() == 1) return clouds.front();
  throw IoError(bag.path() + ": " +
                (clouds.empty()
                     ? "no PointCloud2 topic"
                     : "several PointCloud2 topics (" + joined(clouds) + "): choose one with --points-topic"));
}

struct Cloud {
  BagMessageRef ref;
  double stamp = 0.0;
  std::string frame_id;
};

std::vector<Cloud> clouds_of(const BagReader& bag, const std::string& topic) {
  std::vector<Cloud> clouds;
  for (const BagMessageRef& ref : bag.messages(topic)) {
    RosHeader h;
    if (ref.head.empty()) {
      h = decode_header(bag.data(ref), "PointCloud2");  // indexed from an MCAP summary
    } else {
      try {
        h = decode_header(ref.head, "PointCloud2");
      } catch (const IoError&) {
        h = decode_header(bag.data(ref), "PointCloud2");  // a frame_id longer than the head
      }
    }
    const double stamp = h.stamp_sec != 0 || h.stamp_nanosec != 0 ? h.stamp_s() : 1e-9 * ref.log_time_ns;
    clouds.push_back({ref, stamp, h.frame_id});
  }
  return clouds;
}

// The pose of each cloud's sensor in the map frame (nullopt outside the poses' span), and a
// note saying where the poses came from.
using PoseAt = std::function<std::optional<Pose3d>(const Cloud&)>;

PoseAt poses_from_topic(const BagReader& bag, const std::string& name, const TfTree& statics, std::string* note) {
  const BagTopic& topic = topic_named(bag, name, "--pose-topic");
  const bool odometry = topic.type == kOdometry;
  if (!odometry && topic.type != kPoseStamped)
    throw IoError(bag.path() + ": " + name + " is " + topic.type + ", not " + kOdometry + " or " + kPoseStamped);
  auto track = std::make_shared<Track>();
  std::string child;
  for (const BagMessageRef& ref : bag.messages(name)) {
    const StampedPose p = odometry ? decode_odometry(bag.data(ref)) : decode_pose_stamped(bag.data(ref));
    track->add(p.header.stamp_s(), p.T_parent_child);
    if (child.empty()) child = p.child_frame_id;
  }
  track->sort();
  *note = "poses from " + name + " (" + topic.type + (child.empty() ? "" : ", of frame " + child) + ")";
  // The clouds in another frame than the poses: the static transform between them, found once
  // per cloud frame.
  auto T_child_frame = std::make_shared<std::map<std::string, Pose3d>>();
  return [track, child, statics, T_child_frame, path = bag.path(), name](const Cloud& c) -> std::optional<Pose3d> {
    const std::optional<Pose3d> T_map_child = track->at(c.stamp);
    if (!T_map_child || child.empty() || c.frame_id.empty() || child == c.frame_id) return T_map_child;
    auto known = T_child_frame->find(c.frame_id);
    if (known == T_child_frame->end()) {
      std::string root_child, root_sensor;
      const std::optional<Pose3d> a = to_root(statics, child, 0.0, &root_child),
                                  b = to_root(statics, c.frame_id, 0.0, &root_sensor);
      if (!a || !b || root_child != root_sensor)
        throw IoError(path + ": " + name + " gives poses of frame '" + child + "' and the clouds are in '" +
                      c.frame_id + "', with no static transform between them in /tf_static");
      known = T_child_frame->emplace(c.frame_id, a->inverse() * *b).first;
    }
    return *T_map_child * known->second;
  };
}

PoseAt poses_from_tf(const BagReader& bag, const BagOptions& o, const TfTree& tree, const std::string& cloud_frame,
                     std::string* note) {
  const std::string sensor = o.sensor_frame.empty() ? cloud_frame : o.sensor_frame;
  if (!tree.count(sensor))
    throw IoError(bag.path() + ": frame '" + sensor + "' is not in /tf or /tf_static (--sensor-frame)");
  *note = "poses from /tf: '" + sensor + "' in '" + (o.map_frame.empty() ? "the root frame" : o.map_frame) + "'";
  auto shared = std::make_shared<TfTree>(tree);
  return [shared, sensor, map = o.map_frame, path = bag.path()](const Cloud& c) -> std::optional<Pose3d> {
    std::string root, map_root;
    const std::optional<Pose3d> T_root_sensor = to_root(*shared, sensor, c.stamp, &root);
    if (!T_root_sensor || map.empty() || map == root) return T_root_sensor;
    const std::optional<Pose3d> T_root_map = to_root(*shared, map, c.stamp, &map_root);
    if (!T_root_map) return std::nullopt;
    if (map_root != root) throw IoError(path + ": frames '" + map + "' and '" + sensor + "' are not connected in /tf");
    return T_root_map->inverse() * *T_root_sensor;
  };
}

PoseAt poses_from_file(const std::string& file, std::string* note) {
  const StampedPoses tum = read_tum(file);
  auto track = std::make_shared<Track>();
  for (size_t i = 0; i < tum.poses.size(); ++i) track->add(tum.times[i], tum.poses[i]);
  track->sort();
  *note = "poses from " + file + " (TUM, matched by time)";
  return [track](const Cloud& c) { return track->at(c.stamp); };
}

}  // namespace

Sequence Sequence::open_bag(const std::string& path, const SequenceOptions& options) {
  std::shared_ptr<const BagReader> bag = BagReader::open(path);
  const BagOptions& o = options.bag;
  const std::string topic = points_topic(*bag, o);
  const std::vector<Cloud> clouds = clouds_of(*bag, topic);
  if (clouds.empty()) throw IoError(path + ": " + topic + " has no messages");
  TfTree statics, tree;
  if (!topics_of_type(*bag, {kTf}).empty()) {
    for (const BagTopic& t : bag->topics())
      if (t.type == kTf) add_transforms(*bag, t.name, t.name == "/tf_static", t.name == "/tf_static" ? statics : tree);
    for (auto& [child, edge] : tree) edge.track.sort();
    for (const auto& [child, edge] : statics) tree.emplace(child, edge);
  }
  std::string note;
  PoseAt pose_at;
  if (!options.poses_path.empty()) {
    if (!o.pose_topic.empty() || !o.map_frame.empty())
      throw IoError(path + ": give poses by one source: a file, --pose-topic or /tf");
    pose_at = poses_from_file(options.poses_path, &note);
  } else if (!o.pose_topic.empty()) {
    pose_at = poses_from_topic(*bag, o.pose_topic, statics, &note);
  } else if (!o.map_frame.empty() || !o.sensor_frame.empty()) {
    pose_at = poses_from_tf(*bag, o, tree, clouds.front().frame_id, &note);
  } else {
    const std::vector<std::string> pose_topics = topics_of_type(*bag, {kOdometry, kPoseStamped});
    if (pose_topics.size() == 1)
      pose_at = poses_from_topic(*bag, pose_topics.front(), statics, &note);
    else if (pose_topics.empty() && !tree.empty())
      pose_at = poses_from_tf(*bag, o, tree, clouds.front().frame_id, &note);
    else
      throw IoError(path + ": choose the poses: --pose-topic (Odometry or PoseStamped topics: " + joined(pose_topics) +
                    "), --map-frame for /tf, or a TUM file (--odometry)");
  }
  Sequence seq;
  seq.folder_ = path;
  seq.layout_ = SequenceLayout::kBag;
  seq.has_times_ = true;
  size_t skipped = 0;
  for (const Cloud& c : clouds) {
    const std::optional<Pose3d> T = pose_at(c);
    if (!T) {
      ++skipped;
      continue;
    }
    seq.bag_scans_.push_back(c.ref);
    seq.T_world_lidar_.push_back(*T);
    seq.times_.push_back(c.stamp);
  }
  if (seq.bag_scans_.empty())
    throw IoError(path + ": none of the " + std::to_string(clouds.size()) + " clouds of " + topic +
                  " lies within the poses' time span (" + note + ")");
  seq.source_note_ = "bag " + path + ": " + std::to_string(seq.bag_scans_.size()) + " clouds of " + topic + ", " +
                     note +
                     (skipped ? "; " + std::to_string(skipped) + " clouds outside the poses' time span skipped" : "");
  seq.bag_ = std::move(bag);
  seq.bag_mutex_ = std::make_shared<std::mutex>();
  return seq;
}

}  // namespace io
}  // namespace segmatch
