// The .msg definitions of the types the MCAP writer stores, as rosbag2 concatenates them into a
// schema: tools that decode by schema (Foxglove, `ros2 bag play` on a machine without the
// packages) need every dependency spelled out. Comments of the upstream files are left out;
// fields, constants and defaults are as upstream.
#include "mcap.h"

#include <map>
#include <set>
#include <vector>

namespace segmatch {
namespace io {
namespace detail {
namespace mcap {

namespace {

struct Definition {
  const char* text;
  std::vector<const char*> dependencies;  // "pkg/Name", as the MSG: sections name them
};

const std::map<std::string, Definition>& definitions() {
  static const std::map<std::string, Definition> kDefinitions = {
      {"builtin_interfaces/Time", {"int32 sec\nuint32 nanosec\n", {}}},
      {"std_msgs/Header", {"builtin_interfaces/Time stamp\nstring frame_id\n", {"builtin_interfaces/Time"}}},
      {"sensor_msgs/PointField",
       {"uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\n"
        "uint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n"
        "string name\nuint32 offset\nuint8  datatype\nuint32 count\n",
        {}}},
      {"sensor_msgs/PointCloud2",
       {"std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n"
        "bool    is_bigendian\nuint32  point_step\nuint32  row_step\nuint8[] data\nbool is_dense\n",
        {"std_msgs/Header", "sensor_msgs/PointField"}}},
      {"geometry_msgs/Point", {"float64 x\nfloat64 y\nfloat64 z\n", {}}},
      {"geometry_msgs/Vector3", {"float64 x\nfloat64 y\nfloat64 z\n", {}}},
      {"geometry_msgs/Quaternion", {"float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n", {}}},
      {"geometry_msgs/Pose",
       {"Point position\nQuaternion orientation\n", {"geometry_msgs/Point", "geometry_msgs/Quaternion"}}},
      {"geometry_msgs/PoseWithCovariance", {"Pose pose\nfloat64[36] covariance\n", {"geometry_msgs/Pose"}}},
      {"geometry_msgs/Twist", {"Vector3  linear\nVector3  angular\n", {"geometry_msgs/Vector3"}}},
      {"geometry_msgs/TwistWithCovariance", {"Twist twist\nfloat64[36] covariance\n", {"geometry_msgs/Twist"}}},
      {"geometry_msgs/Transform",
       {"Vector3 translation\nQuaternion rotation\n", {"geometry_msgs/Vector3", "geometry_msgs/Quaternion"}}},
      {"geometry_msgs/TransformStamped",
       {"std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
        {"std_msgs/Header", "geometry_msgs/Transform"}}},
      {"geometry_msgs/PoseStamped", {"std_msgs/Header header\nPose pose\n", {"std_msgs/Header", "geometry_msgs/Pose"}}},
      {"nav_msgs/Odometry",
       {"std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n",
        {"std_msgs/Header", "geometry_msgs/PoseWithCovariance", "geometry_msgs/TwistWithCovariance"}}},
      {"tf2_msgs/TFMessage", {"geometry_msgs/TransformStamped[] transforms\n", {"geometry_msgs/TransformStamped"}}},
  };
  return kDefinitions;
}

// Every type `name` depends on, directly or not, each once, nearest first.
void collect(const std::string& name, std::set<std::string>* seen, std::vector<std::string>* order) {
  std::vector<std::string> queue = {name};
  for (size_t i = 0; i < queue.size(); ++i) {
    for (const char* dependency : definitions().at(queue[i]).dependencies) {
      if (seen->insert(dependency).second) {
        queue.push_back(dependency);
        order->push_back(dependency);
      }
    }
  }
}

}  // namespace

std::string ros2msg_definition(const std::string& type) {
  // "sensor_msgs/msg/PointCloud2" -> "sensor_msgs/PointCloud2", the key of the table.
  const size_t msg = type.find("/msg/");
  const std::string key = msg == std::string::npos ? type : type.substr(0, msg) + type.substr(msg + 4);
  const auto it = definitions().find(key);
  if (msg == std::string::npos || it == definitions().end()) return "";
  std::string text = it->second.text;
  std::set<std::string> seen = {key};
  std::vector<std::string> order;
  collect(key, &seen, &order);
  for (const std::string& dependency : order) {
    text += "================================================================================\nMSG: " + dependency +
            "\n" + definitions().at(dependency).text;
  }
  return text;
}

}  // namespace mcap
}  // namespace detail
}  // namespace io
}  // namespace segmatch
