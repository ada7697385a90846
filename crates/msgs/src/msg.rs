//! ROS 2 message types, field for field as their `.msg` files define them.
//!
//! CDR (the wire format of ROS 2 over DDS, and of rosbag2's MCAP files) has no field names
//! or tags: a struct is its fields in order, each aligned to its own size. So every struct
//! here keeps the `.msg` field order and widths exactly, and the tests compare the bytes with
//! ones a real ROS 2 implementation produced. [`RosMessage`] carries each type's ROS name and
//! `.msg` text, which MCAP needs as the channel's schema.

use serde::de::{self, DeserializeOwned, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A ROS 2 message type: its package, name and definition.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + Send + 'static {
    /// Package, e.g. `sensor_msgs`.
    const PACKAGE: &'static str;
    /// Type name, e.g. `LaserScan`.
    const NAME: &'static str;
    /// The `.msg` text (without comments).
    const DEFINITION: &'static str;
    /// The message types this one uses, directly or not (`pkg/msg/Name`), each once.
    const DEPENDS: &'static [&'static str];

    /// The ROS 2 name, `pkg/msg/Name` (rosbag2's and MCAP's schema name).
    fn type_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }

    /// The `ros2msg` schema: this definition, then each dependency's under a `MSG:` line, as
    /// rosbag2 writes it.
    fn schema_text() -> String {
        let mut s = Self::DEFINITION.to_string();
        for dep in Self::DEPENDS {
            let def = definition_of(dep).expect("every dependency is defined here");
            s.push_str("\n================================================================================\n");
            s.push_str(&format!("MSG: {}\n", dep.replace("/msg/", "/")));
            s.push_str(def);
        }
        s
    }
}

fn definition_of(full_name: &str) -> Option<&'static str> {
    Some(match full_name {
        "builtin_interfaces/msg/Time" => Time::DEFINITION,
        "std_msgs/msg/Header" => Header::DEFINITION,
        "geometry_msgs/msg/Vector3" => Vector3::DEFINITION,
        "geometry_msgs/msg/Point" => Point::DEFINITION,
        "geometry_msgs/msg/Quaternion" => Quaternion::DEFINITION,
        "geometry_msgs/msg/Pose" => Pose::DEFINITION,
        "geometry_msgs/msg/PoseWithCovariance" => PoseWithCovariance::DEFINITION,
        "geometry_msgs/msg/Twist" => Twist::DEFINITION,
        "geometry_msgs/msg/TwistWithCovariance" => TwistWithCovariance::DEFINITION,
        "geometry_msgs/msg/Transform" => Transform::DEFINITION,
        "geometry_msgs/msg/TransformStamped" => TransformStamped::DEFINITION,
        "geometry_msgs/msg/PoseStamped" => PoseStamped::DEFINITION,
        "nav_msgs/msg/MapMetaData" => MapMetaData::DEFINITION,
        "builtin_interfaces/msg/Duration" => Duration::DEFINITION,
        "std_msgs/msg/ColorRGBA" => ColorRGBA::DEFINITION,
        "sensor_msgs/msg/CompressedImage" => CompressedImage::DEFINITION,
        "visualization_msgs/msg/UVCoordinate" => UVCoordinate::DEFINITION,
        "visualization_msgs/msg/MeshFile" => MeshFile::DEFINITION,
        "visualization_msgs/msg/Marker" => Marker::DEFINITION,
        "std_msgs/msg/Empty" => Empty::DEFINITION,
        _ => return None,
    })
}

macro_rules! ros_message {
    ($ty:ty, $pkg:literal, $name:literal, [$($dep:literal),*], $def:literal) => {
        impl RosMessage for $ty {
            const PACKAGE: &'static str = $pkg;
            const NAME: &'static str = $name;
            const DEFINITION: &'static str = $def;
            const DEPENDS: &'static [&'static str] = &[$($dep),*];
        }
    };
}

/// `builtin_interfaces/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second, `0..1e9`.
    pub nanosec: u32,
}

impl Time {
    /// The time `t` seconds after the epoch (rounded to the nanosecond).
    pub fn from_secs(t: f64) -> Self {
        let sec = t.floor();
        let nanosec = ((t - sec) * 1e9).round().min(999_999_999.0) as u32;
        Self { sec: sec as i32, nanosec }
    }

    /// Seconds since the epoch.
    pub fn as_secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }

    /// Nanoseconds since the epoch (MCAP's log time).
    pub fn as_nanos(&self) -> u64 {
        (self.sec.max(0) as u64) * 1_000_000_000 + self.nanosec as u64
    }
}
ros_message!(Time, "builtin_interfaces", "Time", [], "int32 sec\nuint32 nanosec\n");

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Acquisition time.
    pub stamp: Time,
    /// Frame the data is expressed in.
    pub frame_id: String,
}
ros_message!(
    Header,
    "std_msgs",
    "Header",
    ["builtin_interfaces/msg/Time"],
    "builtin_interfaces/Time stamp\nstring frame_id\n"
);

impl Header {
    /// A header for `frame_id` at `stamp`.
    pub fn new(stamp: Time, frame_id: &str) -> Self {
        Self { stamp, frame_id: frame_id.to_string() }
    }
}

/// `std_msgs/String`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StringMsg {
    /// The text.
    pub data: String,
}
ros_message!(StringMsg, "std_msgs", "String", [], "string data\n");

/// `geometry_msgs/Vector3`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}
ros_message!(Vector3, "geometry_msgs", "Vector3", [], "float64 x\nfloat64 y\nfloat64 z\n");

/// `geometry_msgs/Point`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}
ros_message!(Point, "geometry_msgs", "Point", [], "float64 x\nfloat64 y\nfloat64 z\n");

/// `geometry_msgs/Quaternion` (identity by default, as in ROS).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}
ros_message!(Quaternion, "geometry_msgs", "Quaternion", [], "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n");

impl Default for Quaternion {
    fn default() -> Self {
        Self { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl Quaternion {
    /// A rotation by `yaw` about z.
    pub fn from_yaw(yaw: f64) -> Self {
        let h = 0.5 * yaw;
        Self { x: 0.0, y: 0.0, z: h.sin(), w: h.cos() }
    }

    /// The rotation's yaw (about z), for any unit quaternion; NaN if it has NaN parts.
    pub fn yaw(&self) -> f64 {
        let Self { x, y, z, w } = *self;
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }

    /// Whether the parts are finite and the norm is 1 within `tol`.
    pub fn is_unit(&self, tol: f64) -> bool {
        let n = self.x * self.x + self.y * self.y + self.z * self.z + self.w * self.w;
        n.is_finite() && (n.sqrt() - 1.0).abs() <= tol
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}
ros_message!(
    Pose,
    "geometry_msgs",
    "Pose",
    ["geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"],
    "Point position\nQuaternion orientation\n"
);

impl Pose {
    /// A planar pose.
    pub fn planar(x: f64, y: f64, yaw: f64) -> Self {
        Self { position: Point { x, y, z: 0.0 }, orientation: Quaternion::from_yaw(yaw) }
    }
}

/// A row-major 6x6 covariance, `float64[36]` (fixed size: no length on the wire).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance(pub [f64; 36]);

impl Default for Covariance {
    fn default() -> Self {
        Self([0.0; 36])
    }
}

impl Serialize for Covariance {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Covariance;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64 values")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance, A::Error> {
                let mut c = [0.0; 36];
                for (i, v) in c.iter_mut().enumerate() {
                    *v = seq.next_element()?.ok_or_else(|| de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance(c))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: Pose,
    /// Covariance of (x, y, z, roll, pitch, yaw).
    pub covariance: Covariance,
}
ros_message!(
    PoseWithCovariance,
    "geometry_msgs",
    "PoseWithCovariance",
    ["geometry_msgs/msg/Pose", "geometry_msgs/msg/Point", "geometry_msgs/msg/Quaternion"],
    "Pose pose\nfloat64[36] covariance\n"
);

/// `geometry_msgs/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity (m/s).
    pub linear: Vector3,
    /// Angular velocity (rad/s).
    pub angular: Vector3,
}
ros_message!(Twist, "geometry_msgs", "Twist", ["geometry_msgs/msg/Vector3"], "Vector3 linear\nVector3 angular\n");

impl Twist {
    /// A planar twist: forward speed and yaw rate.
    pub fn planar(linear: f64, angular: f64) -> Self {
        Self {
            linear: Vector3 { x: linear, ..Default::default() },
            angular: Vector3 { z: angular, ..Default::default() },
        }
    }
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// Twist.
    pub twist: Twist,
    /// Covariance.
    pub covariance: Covariance,
}
ros_message!(
    TwistWithCovariance,
    "geometry_msgs",
    "TwistWithCovariance",
    ["geometry_msgs/msg/Twist", "geometry_msgs/msg/Vector3"],
    "Twist twist\nfloat64[36] covariance\n"
);

/// `geometry_msgs/TwistStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    /// Header.
    pub header: Header,
    /// Twist.
    pub twist: Twist,
}
ros_message!(
    TwistStamped,
    "geometry_msgs",
    "TwistStamped",
    ["std_msgs/msg/Header", "builtin_interfaces/msg/Time", "geometry_msgs/msg/Twist", "geometry_msgs/msg/Vector3"],
    "std_msgs/Header header\nTwist twist\n"
);

/// `geometry_msgs/PoseStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// Pose.
    pub pose: Pose,
}
ros_message!(
    PoseStamped,
    "geometry_msgs",
    "PoseStamped",
    [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion"
    ],
    "std_msgs/Header header\nPose pose\n"
);

/// `nav_msgs/Path`: a plan, as Nav2's planner server publishes it on `/plan`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Header (the frame of the poses, usually `map`).
    pub header: Header,
    /// The poses from the start to the goal.
    pub poses: Vec<PoseStamped>,
}
ros_message!(
    Path,
    "nav_msgs",
    "Path",
    [
        "geometry_msgs/msg/PoseStamped",
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion"
    ],
    "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n"
);

/// `std_msgs/Empty`. ROS 2's IDL gives a structure without fields one byte,
/// `structure_needs_at_least_one_member`, and that byte is on the wire (an action's empty
/// result part, as in `nav2_msgs/FollowPath`, carries it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Empty {
    /// Always 0; there only because IDL structures cannot be empty.
    pub structure_needs_at_least_one_member: u8,
}
ros_message!(Empty, "std_msgs", "Empty", [], "");

/// `nav2_msgs/action/FollowPath` as ROS 2 Jazzy's Nav2 defines it: the action
/// `controller_server` serves as `follow_path` and bt_navigator's FollowPath node calls. The
/// three parts are the structs an action's wire types wrap (`FollowPath_SendGoal_Request_`
/// holds the goal id and a [`FollowPathGoal`], `FollowPath_GetResult_Response_` a status and a
/// [`FollowPathResult`], `FollowPath_FeedbackMessage_` a goal id and a [`FollowPathFeedback`]).
pub mod follow_path {
    use super::{Empty, Path};
    use serde::{Deserialize, Serialize};

    /// The action's package and name (`nav2_msgs/action/FollowPath`).
    pub const PACKAGE: &str = "nav2_msgs";
    /// The action's name within its package.
    pub const NAME: &str = "FollowPath";

    /// The goal: a path to follow and the plugins to use for it.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowPathGoal {
        /// The path, usually in `map`.
        pub path: Path,
        /// Which controller plugin (`FollowPath` in Nav2's default behaviour trees).
        pub controller_id: String,
        /// Which goal checker plugin.
        pub goal_checker_id: String,
        /// Which progress checker plugin (new in Jazzy).
        pub progress_checker_id: String,
    }

    /// The result: an error code (0 on success) and a message saying why.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowPathResult {
        /// Nothing (`std_msgs/Empty`).
        pub result: Empty,
        /// One of the constants below.
        pub error_code: u16,
        /// Why it failed (empty on success).
        pub error_msg: String,
    }

    /// Jazzy's error codes (`FollowPath.action`), in its priority order.
    impl FollowPathResult {
        /// No error.
        pub const NONE: u16 = 0;
        /// An error of no other kind.
        pub const UNKNOWN: u16 = 100;
        /// The controller id names no controller.
        pub const INVALID_CONTROLLER: u16 = 101;
        /// A transform was missing.
        pub const TF_ERROR: u16 = 102;
        /// The path is empty or unusable.
        pub const INVALID_PATH: u16 = 103;
        /// The controller's patience ran out.
        pub const PATIENCE_EXCEEDED: u16 = 104;
        /// The progress checker saw the robot not moving.
        pub const FAILED_TO_MAKE_PROGRESS: u16 = 105;
        /// The controller could not compute a command.
        pub const NO_VALID_CONTROL: u16 = 106;
        /// The controller took too long.
        pub const CONTROLLER_TIMED_OUT: u16 = 107;

        /// A failure with `code` and its reason.
        pub fn error(code: u16, msg: impl Into<String>) -> Self {
            Self { result: Empty::default(), error_code: code, error_msg: msg.into() }
        }
    }

    /// The feedback while driving.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct FollowPathFeedback {
        /// Path length left to the path's end (m).
        pub distance_to_goal: f32,
        /// The robot's speed (m/s).
        pub speed: f32,
    }
}

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}
ros_message!(
    Transform,
    "geometry_msgs",
    "Transform",
    ["geometry_msgs/msg/Vector3", "geometry_msgs/msg/Quaternion"],
    "Vector3 translation\nQuaternion rotation\n"
);

/// `geometry_msgs/TransformStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Header (the parent frame).
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// The child frame's pose in the parent.
    pub transform: Transform,
}
ros_message!(
    TransformStamped,
    "geometry_msgs",
    "TransformStamped",
    [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Transform",
        "geometry_msgs/msg/Vector3",
        "geometry_msgs/msg/Quaternion"
    ],
    "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
);

impl TransformStamped {
    /// A planar transform from `parent` to `child` at `stamp`.
    pub fn planar(stamp: Time, parent: &str, child: &str, x: f64, y: f64, yaw: f64) -> Self {
        Self {
            header: Header::new(stamp, parent),
            child_frame_id: child.to_string(),
            transform: Transform { translation: Vector3 { x, y, z: 0.0 }, rotation: Quaternion::from_yaw(yaw) },
        }
    }
}

/// `sensor_msgs/LaserScan`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Header (the sensor frame, time of the first beam).
    pub header: Header,
    /// Angle of the first beam (rad).
    pub angle_min: f32,
    /// Angle of the last beam (rad).
    pub angle_max: f32,
    /// Angle between beams (rad).
    pub angle_increment: f32,
    /// Time between beams (s).
    pub time_increment: f32,
    /// Time between scans (s).
    pub scan_time: f32,
    /// Closest valid range (m).
    pub range_min: f32,
    /// Farthest valid range (m).
    pub range_max: f32,
    /// Ranges (m).
    pub ranges: Vec<f32>,
    /// Intensities (device units), empty if the device gives none.
    pub intensities: Vec<f32>,
}
ros_message!(
    LaserScan,
    "sensor_msgs",
    "LaserScan",
    ["std_msgs/msg/Header", "builtin_interfaces/msg/Time"],
    "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n"
);

/// `nav_msgs/Odometry`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Header (the odometry frame).
    pub header: Header,
    /// The body frame.
    pub child_frame_id: String,
    /// Pose in the header's frame.
    pub pose: PoseWithCovariance,
    /// Velocity in the child frame.
    pub twist: TwistWithCovariance,
}
ros_message!(
    Odometry,
    "nav_msgs",
    "Odometry",
    [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/PoseWithCovariance",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/TwistWithCovariance",
        "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/Vector3"
    ],
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n"
);

/// `tf2_msgs/TFMessage`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TFMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}
ros_message!(
    TFMessage,
    "tf2_msgs",
    "TFMessage",
    [
        "geometry_msgs/msg/TransformStamped",
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Transform",
        "geometry_msgs/msg/Vector3",
        "geometry_msgs/msg/Quaternion"
    ],
    "geometry_msgs/TransformStamped[] transforms\n"
);

/// `nav_msgs/MapMetaData`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    /// When the map was loaded.
    pub map_load_time: Time,
    /// Cell size (m).
    pub resolution: f32,
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Pose of cell (0, 0)'s lower-left corner in the map frame.
    pub origin: Pose,
}
ros_message!(
    MapMetaData,
    "nav_msgs",
    "MapMetaData",
    [
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion"
    ],
    "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n"
);

/// `nav_msgs/OccupancyGrid`: a map, as `map_server` publishes it on `/map`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Header (frame `map`).
    pub header: Header,
    /// Size, resolution and origin.
    pub info: MapMetaData,
    /// Row-major from cell (0, 0): 0 free, 100 occupied, -1 unknown.
    pub data: Vec<i8>,
}
ros_message!(
    OccupancyGrid,
    "nav_msgs",
    "OccupancyGrid",
    [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "nav_msgs/msg/MapMetaData",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion"
    ],
    "std_msgs/Header header\nMapMetaData info\nint8[] data\n"
);

/// `rosgraph_msgs/Clock`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    /// The simulated time.
    pub clock: Time,
}
ros_message!(Clock, "rosgraph_msgs", "Clock", ["builtin_interfaces/msg/Time"], "builtin_interfaces/Time clock\n");

/// `builtin_interfaces/Duration`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Duration {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds past `sec`.
    pub nanosec: u32,
}
ros_message!(Duration, "builtin_interfaces", "Duration", [], "int32 sec\nuint32 nanosec\n");

/// `std_msgs/ColorRGBA`: components in [0, 1].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRGBA {
    /// Red.
    pub r: f32,
    /// Green.
    pub g: f32,
    /// Blue.
    pub b: f32,
    /// Opacity.
    pub a: f32,
}
ros_message!(ColorRGBA, "std_msgs", "ColorRGBA", [], "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n");

/// `sensor_msgs/CompressedImage` (a marker's texture; rlnav sends it empty).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// `jpeg`, `png`...
    pub format: String,
    /// The compressed bytes.
    pub data: Vec<u8>,
}
ros_message!(
    CompressedImage,
    "sensor_msgs",
    "CompressedImage",
    ["std_msgs/msg/Header", "builtin_interfaces/msg/Time"],
    "std_msgs/Header header\nstring format\nuint8[] data\n"
);

/// `visualization_msgs/UVCoordinate`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UVCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}
ros_message!(UVCoordinate, "visualization_msgs", "UVCoordinate", [], "float32 u\nfloat32 v\n");

/// `visualization_msgs/MeshFile`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    /// File name (its extension gives the format).
    pub filename: String,
    /// The file's bytes.
    pub data: Vec<u8>,
}
ros_message!(MeshFile, "visualization_msgs", "MeshFile", [], "string filename\nuint8[] data\n");

/// `visualization_msgs/Marker` (ROS 2 Jazzy's fields): a shape RViz2 and Foxglove draw.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    /// Header (the frame the pose is in).
    pub header: Header,
    /// Namespace; with `id`, what a later marker replaces.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// Shape: [`Marker::CUBE`], [`Marker::CYLINDER`]...
    #[serde(rename = "type")]
    pub kind: i32,
    /// [`Marker::ADD`], [`Marker::DELETE`] or [`Marker::DELETEALL`].
    pub action: i32,
    /// Pose of the shape's centre.
    pub pose: Pose,
    /// Size (m) along the shape's axes.
    pub scale: Vector3,
    /// Colour.
    pub color: ColorRGBA,
    /// How long it lasts (0: until replaced).
    pub lifetime: Duration,
    /// Re-transformed into its frame every time it is drawn.
    pub frame_locked: bool,
    /// Points of line and list shapes.
    pub points: Vec<Point>,
    /// Per-point colours.
    pub colors: Vec<ColorRGBA>,
    /// Texture resource.
    pub texture_resource: String,
    /// Texture.
    pub texture: CompressedImage,
    /// Texture coordinates.
    pub uv_coordinates: Vec<UVCoordinate>,
    /// Text of a text marker.
    pub text: String,
    /// Mesh resource.
    pub mesh_resource: String,
    /// Mesh file.
    pub mesh_file: MeshFile,
    /// Use the mesh's own materials.
    pub mesh_use_embedded_materials: bool,
}
ros_message!(
    Marker,
    "visualization_msgs",
    "Marker",
    [
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Vector3",
        "std_msgs/msg/ColorRGBA",
        "builtin_interfaces/msg/Duration",
        "sensor_msgs/msg/CompressedImage",
        "visualization_msgs/msg/UVCoordinate",
        "visualization_msgs/msg/MeshFile"
    ],
    "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\nint32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\nint32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\nint32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\nstd_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n"
);

impl Marker {
    /// A box.
    pub const CUBE: i32 = 1;
    /// A sphere.
    pub const SPHERE: i32 = 2;
    /// An upright cylinder.
    pub const CYLINDER: i32 = 3;
    /// Line segments between consecutive point pairs.
    pub const LINE_LIST: i32 = 5;
    /// Triangles, three points each.
    pub const TRIANGLE_LIST: i32 = 11;
    /// Add or replace.
    pub const ADD: i32 = 0;
    /// Remove `ns`/`id`.
    pub const DELETE: i32 = 2;
    /// Remove every marker of the topic.
    pub const DELETEALL: i32 = 3;
}

/// `visualization_msgs/MarkerArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    /// The markers, applied in order.
    pub markers: Vec<Marker>,
}
ros_message!(
    MarkerArray,
    "visualization_msgs",
    "MarkerArray",
    [
        "visualization_msgs/msg/Marker",
        "std_msgs/msg/Header",
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Quaternion",
        "geometry_msgs/msg/Vector3",
        "std_msgs/msg/ColorRGBA",
        "builtin_interfaces/msg/Duration",
        "sensor_msgs/msg/CompressedImage",
        "visualization_msgs/msg/UVCoordinate",
        "visualization_msgs/msg/MeshFile"
    ],
    "Marker[] markers\n"
);

/// CDR encapsulation header for little-endian plain CDR, as ROS 2 writes it.
pub const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Errors decoding a serialized message.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// Fewer than the 4 bytes of the encapsulation header.
    #[error("{ty}: {len} bytes is too short for a CDR message (4-byte header expected)")]
    Short {
        /// The message type.
        ty: String,
        /// How many bytes arrived.
        len: usize,
    },
    /// An encapsulation other than plain CDR.
    #[error("{ty}: unsupported CDR encapsulation {kind:#06x} (expected plain CDR, 0x0000 or 0x0001)")]
    Encapsulation {
        /// The message type.
        ty: String,
        /// The encapsulation kind read.
        kind: u16,
    },
    /// The body does not decode.
    #[error("{ty}: malformed CDR: {reason}")]
    Malformed {
        /// The message type.
        ty: String,
        /// What the decoder said.
        reason: String,
    },
}

/// Serializes a message as ROS 2 does: the CDR encapsulation header, then little-endian CDR.
pub fn to_cdr<M: RosMessage>(m: &M) -> Vec<u8> {
    let body =
        cdr_encoding::to_vec::<M, byteorder::LittleEndian>(m).expect("CDR serialization of plain structs cannot fail");
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    out
}

/// Deserializes a message with its encapsulation header (either byte order).
pub fn from_cdr<M: RosMessage>(bytes: &[u8]) -> Result<M, DecodeError> {
    if bytes.len() < 4 {
        return Err(DecodeError::Short { ty: M::type_name(), len: bytes.len() });
    }
    let kind = u16::from_be_bytes([bytes[0], bytes[1]]);
    let body = &bytes[4..];
    let result = match kind {
        0x0000 => cdr_encoding::from_bytes::<M, byteorder::BigEndian>(body),
        0x0001 => cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body),
        _ => return Err(DecodeError::Encapsulation { ty: M::type_name(), kind }),
    };
    result.map(|(m, _)| m).map_err(|e| DecodeError::Malformed { ty: M::type_name(), reason: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternion_yaw_round_trips() {
        for yaw in [-3.1, -1.0, 0.0, 0.5, 2.0, 3.1] {
            let q = Quaternion::from_yaw(yaw);
            assert!(q.is_unit(1e-12));
            assert!((q.yaw() - yaw).abs() < 1e-12);
        }
    }

    #[test]
    fn time_converts() {
        let t = Time::from_secs(12.25);
        assert_eq!(t, Time { sec: 12, nanosec: 250_000_000 });
        assert_eq!(t.as_nanos(), 12_250_000_000);
        assert!((t.as_secs() - 12.25).abs() < 1e-12);
    }

    #[test]
    fn schema_lists_every_dependency_once() {
        let s = Odometry::schema_text();
        assert!(s.starts_with("std_msgs/Header header\n"));
        for dep in Odometry::DEPENDS {
            let line = format!("MSG: {}\n", dep.replace("/msg/", "/"));
            assert_eq!(s.matches(&line).count(), 1, "{dep}");
        }
        // Every type a definition names must be among the dependencies.
        for ty in ["Header", "Time", "PoseWithCovariance", "Pose", "Point", "Quaternion", "Twist", "Vector3"] {
            assert!(Odometry::DEPENDS.iter().any(|d| d.ends_with(&format!("/{ty}"))), "{ty}");
        }
    }

    /// The FollowPath parts in CDR, laid out by hand from the IDL: the empty result's one byte,
    /// then the error code at 2, then the message's length at 4; the goal's three strings
    /// after the path.
    #[test]
    fn follow_path_parts_have_the_idl_layout() {
        use follow_path::*;
        fn le<T: Serialize>(v: &T) -> Vec<u8> {
            cdr_encoding::to_vec::<T, byteorder::LittleEndian>(v).unwrap()
        }
        let r = FollowPathResult::error(FollowPathResult::INVALID_PATH, "ab");
        assert_eq!(le(&r), [0, 0, 103, 0, 3, 0, 0, 0, b'a', b'b', 0]);
        let f = FollowPathFeedback { distance_to_goal: 1.0, speed: 0.5 };
        assert_eq!(le(&f), [0, 0, 0x80, 0x3f, 0, 0, 0, 0x3f]);
        let g = FollowPathGoal { controller_id: "FollowPath".into(), ..Default::default() };
        let path = le(&g.path);
        let bytes = le(&g);
        // An empty path: stamp (8), frame "" (4 + 1), padding to 4, no poses (4).
        assert_eq!(path.len(), 20);
        assert_eq!(&bytes[..20], &path[..]);
        assert_eq!(&bytes[20..24], &11u32.to_le_bytes());
        assert_eq!(&bytes[24..35], b"FollowPath\0");
        let (back, _) = cdr_encoding::from_bytes::<FollowPathGoal, byteorder::LittleEndian>(&bytes).unwrap();
        assert_eq!(back, g);
        assert_eq!(le(&Empty::default()), [0]);
    }

    #[test]
    fn truncated_and_foreign_bytes_are_errors() {
        let scan = LaserScan { ranges: vec![1.0; 10], ..Default::default() };
        let bytes = to_cdr(&scan);
        for cut in [0, 3, 4, 10, bytes.len() - 1] {
            assert!(from_cdr::<LaserScan>(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut xcdr2 = bytes.clone();
        xcdr2[1] = 0x07;
        assert!(matches!(from_cdr::<LaserScan>(&xcdr2), Err(DecodeError::Encapsulation { .. })));
        assert_eq!(from_cdr::<LaserScan>(&bytes).unwrap(), scan);
    }
}
