// The ROS 2 message definitions the writers need, in the "ros2msg" form rosbag2 stores in bags:
// the type's own .msg text first, then each type it uses (depth first, each once) after an empty
// line, a line of 80 '=' and a line "MSG: package/Type" (rosbag2's separator). The field lists are those of ROS 2's sensor_msgs,
// std_msgs and builtin_interfaces (Humble to Rolling); the comments are ours, kept on purpose so
// that readers meet comments, blank lines and trailing "# ..." as in real bags.

const TEXTS = {
  "builtin_interfaces/msg/Time": `# A point in time: seconds and nanoseconds since the epoch.
int32 sec
uint32 nanosec
`,
  "std_msgs/msg/Header": `# Stamp and coordinate frame of the data that follows.
builtin_interfaces/Time stamp

# The frame the data is expressed in.
string frame_id
`,
  "sensor_msgs/msg/RegionOfInterest": `# A window of the image (all zero: the full image).
uint32 x_offset
uint32 y_offset
uint32 height
uint32 width
bool do_rectify
`,
  "sensor_msgs/msg/Image": `# An uncompressed image; (0, 0) is the top-left pixel.

std_msgs/Header header  # acquisition time and optical frame

uint32 height           # rows
uint32 width            # columns

string encoding         # pixel layout: mono8, rgb8, bgr8, 16UC1, ...

uint8 is_bigendian      # byte order of multi-byte pixels
uint32 step             # bytes per row
uint8[] data            # step * height bytes
`,
  "sensor_msgs/msg/CompressedImage": `# A compressed image: a JPEG or PNG file's bytes, or compressedDepth.

std_msgs/Header header  # acquisition time and optical frame

string format           # e.g. "jpeg", "rgb8; png compressed bgr8", "16UC1; compressedDepth png"
uint8[] data            # the compressed bytes
`,
  "sensor_msgs/msg/CameraInfo": `# Calibration of a camera (pinhole model and distortion).

std_msgs/Header header

# Size of the images the calibration is for.
uint32 height
uint32 width

string distortion_model   # e.g. plumb_bob
float64[] d               # distortion coefficients

float64[9] k  # intrinsic matrix, 3x3 row-major
float64[9] r  # rectification rotation, 3x3 row-major
float64[12] p # projection matrix, 3x4 row-major

# Binning (0 means 1) and region of interest (all zero means the full image).
uint32 binning_x
uint32 binning_y
RegionOfInterest roi
`,
};

// "pkg/msg/Name" of a field type as written in a .msg ("pkg/Name", or "Name" in the same package).
function qualify(type, ownPackage) {
  const parts = type.split("/");
  return parts.length === 1 ? `${ownPackage}/msg/${type}` : `${parts[0]}/msg/${parts[parts.length - 1]}`;
}

// The complex types a .msg text uses, in order of their fields.
function fieldTypes(name) {
  const ownPackage = name.split("/")[0];
  const types = [];
  for (const raw of TEXTS[name].split("\n")) {
    const line = raw.replace(/#.*/, "").trim();
    if (!line) continue;
    const type = line.split(/\s+/)[0].replace(/\[.*\]$/, "");
    if (/^[A-Z]/.test(type) || type.includes("/")) types.push(qualify(type, ownPackage));
  }
  return types;
}

// The full ros2msg definition of `name` (e.g. "sensor_msgs/msg/Image").
export function fullDefinition(name) {
  if (!(name in TEXTS)) throw new Error(`no definition for ${name}`);
  const seen = new Set([name]);
  const order = [];
  const visit = (type) => {
    for (const used of fieldTypes(type)) {
      if (seen.has(used)) continue;
      seen.add(used);
      order.push(used);
      visit(used);
    }
  };
  visit(name);
  let text = TEXTS[name];
  for (const used of order) {
    text += `\n${"=".repeat(80)}\nMSG: ${used.replace("/msg/", "/")}\n${TEXTS[used]}`;
  }
  return text;
}

export const MESSAGE_TYPES = Object.keys(TEXTS);
