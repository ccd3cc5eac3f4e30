// ROS 2 (Humble) .msg definitions of the types this tool writes, and the
// "complete message definition" text (encoding "ros2msg") built the way
// rosbag2 builds it: the root .msg text, then for every dependency (sorted by
// name, depth first, each one only once) "\n", a line of 80 '=', a line
// "MSG: <type as written in the field>", and that type's .msg text.
//
// The field lines (types, names, array sizes, constants, default values) are
// the standard ROS 2 interfaces. The comment lines are short summaries written
// for this tool (they are not the upstream comment text); they are kept so a
// reader's .msg parser is exercised on comments and blank lines too.

export const MSG_TEXT = {
  "builtin_interfaces/Time": `# Time since the epoch: whole seconds plus nanoseconds.

int32 sec

# Always in [0, 999999999].
uint32 nanosec
`,

  "std_msgs/Header": `# Stamp and coordinate frame of a stamped message.

# Acquisition time of the data.
builtin_interfaces/Time stamp

# Frame the data is expressed in.
string frame_id
`,

  "sensor_msgs/PointField": `# Describes one channel of a PointCloud2 point.

uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8

# Common field names are x, y, z, intensity, rgb, ring.
string name      # name of the field
uint32 offset    # byte offset from the start of the point
uint8  datatype  # one of the constants above
uint32 count     # number of elements in the field
`,

  "sensor_msgs/PointCloud2": `# A collection of N-dimensional points with an arbitrary binary layout.
# 2D (organized) clouds have height > 1; unordered clouds have height 1.

std_msgs/Header header

# Dimensions of the cloud.
uint32 height
uint32 width

# Layout of one point in data.
PointField[] fields

bool    is_bigendian # byte order of data
uint32  point_step   # bytes per point
uint32  row_step     # bytes per row
uint8[] data         # row_step * height bytes

bool is_dense        # true when there are no invalid points
`,

  "geometry_msgs/Point": `# A position in free space.

float64 x
float64 y
float64 z
`,

  "geometry_msgs/Quaternion": `# An orientation as a quaternion.

float64 x 0
float64 y 0
float64 z 0
float64 w 1
`,

  "geometry_msgs/Pose": `# A position and an orientation.

Point position
Quaternion orientation
`,

  "geometry_msgs/PoseWithCovariance": `# A pose with its uncertainty.

Pose pose

# Row-major 6x6 covariance of (x, y, z, rot x, rot y, rot z).
float64[36] covariance
`,

  "geometry_msgs/Vector3": `# A free-space vector.

float64 x
float64 y
float64 z
`,

  "geometry_msgs/Twist": `# Linear and angular velocity.

Vector3  linear
Vector3  angular
`,

  "geometry_msgs/TwistWithCovariance": `# A twist with its uncertainty.

Twist twist

# Row-major 6x6 covariance of (x, y, z, rot x, rot y, rot z).
float64[36] covariance
`,

  "geometry_msgs/Transform": `# The transform between two coordinate frames.

Vector3 translation
Quaternion rotation
`,

  "geometry_msgs/TransformStamped": `# A transform from header.frame_id to child_frame_id.

std_msgs/Header header

# Frame id of the child frame.
string child_frame_id

Transform transform
`,

  "nav_msgs/Odometry": `# An estimate of position and velocity in free space.
# The pose is in header.frame_id, the twist in child_frame_id.

std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
`,

  "tf2_msgs/TFMessage": `geometry_msgs/TransformStamped[] transforms
`,
};

const PRIMITIVES = new Set([
  "bool", "byte", "char", "float32", "float64", "int8", "uint8",
  "int16", "uint16", "int32", "uint32", "int64", "uint64", "string",
]);

// Field types named at the start of a line (the same rule rosbag2 uses).
function dependencies(text, pkg) {
  const deps = new Set();
  const re = /(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+/g;
  for (const m of text.matchAll(re)) {
    const t = m[1];
    if (PRIMITIVES.has(t)) continue;
    deps.add(t.includes("/") ? t : `${pkg}/${t}`);
  }
  return [...deps].sort();
}

// "sensor_msgs/msg/PointCloud2" -> "sensor_msgs/PointCloud2"
export function shortName(type) {
  const p = type.split("/");
  if (p.length === 3) return `${p[0]}/${p[2]}`;
  return type;
}

export function fullDefinition(rosType) {
  const seen = new Set();
  const append = (name, depth) => {
    if (depth <= 0) throw new Error(`definition of ${rosType} recurses too deeply`);
    const key = shortName(name);
    const text = MSG_TEXT[key];
    if (text === undefined) throw new Error(`no .msg text for ${name}`);
    let out = text;
    for (const dep of dependencies(text, key.split("/")[0])) {
      if (seen.has(dep)) continue;
      seen.add(dep);
      out += "\n" + "=".repeat(80) + "\nMSG: " + dep + "\n" + append(dep, depth - 1);
    }
    return out;
  };
  return append(rosType, 50);
}

// Offered QoS profile list as rosbag2 (Humble) stores it (a YAML string).
export function qosYaml({ reliability = 1, durability = 2 } = {}) {
  const inf = "    sec: 2147483647\n    nsec: 4294967295\n";
  return (
    "- history: 3\n" +
    "  depth: 0\n" +
    `  reliability: ${reliability}\n` +
    `  durability: ${durability}\n` +
    "  deadline:\n" + inf +
    "  lifespan:\n" + inf +
    "  liveliness: 1\n" +
    "  liveliness_lease_duration:\n" + inf +
    "  avoid_ros_namespace_conventions: false"
  );
}

export const POINTFIELD = { INT8: 1, UINT8: 2, INT16: 3, UINT16: 4, INT32: 5, UINT32: 6, FLOAT32: 7, FLOAT64: 8 };
export const POINTFIELD_SIZE = { 1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 8: 8 };
