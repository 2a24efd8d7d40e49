//! The ROS 2 message types the bridge speaks, as their interface definitions (field lines only).
//!
//! These are the public interfaces of ROS 2's standard packages (common_interfaces,
//! rcl_interfaces, ackermann_msgs), the same in Humble and Jazzy. They are the one source the
//! bridge derives everything from: the CDR layout its structs must follow (crates/ros2/src/messages.rs,
//! checked by a test), the type hash in every key (RIHS01) and the `ros2msg` schema in
//! recordings. Comments, constants and default values are left out: none of them changes the
//! layout or the hash.

/// `(full name, field lines)` for every type the bridge sends or receives, and every type those
/// refer to. A field's type is a primitive, `string`, or another type of this table given as
/// `package/Type` (a bare `Type` means the same package); `[]` is a sequence, `[N]` an array.
pub(crate) const TYPES: &[(&str, &str)] = &[
    ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec"),
    ("builtin_interfaces/msg/Duration", "int32 sec\nuint32 nanosec"),
    ("std_msgs/msg/Header", "builtin_interfaces/Time stamp\nstring frame_id"),
    ("std_msgs/msg/ColorRGBA", "float32 r\nfloat32 g\nfloat32 b\nfloat32 a"),
    ("std_msgs/msg/MultiArrayDimension", "string label\nuint32 size\nuint32 stride"),
    ("std_msgs/msg/MultiArrayLayout", "MultiArrayDimension[] dim\nuint32 data_offset"),
    ("std_msgs/msg/Float64MultiArray", "MultiArrayLayout layout\nfloat64[] data"),
    ("geometry_msgs/msg/Point", "float64 x\nfloat64 y\nfloat64 z"),
    ("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
    ("geometry_msgs/msg/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w"),
    ("geometry_msgs/msg/Pose", "Point position\nQuaternion orientation"),
    ("geometry_msgs/msg/PoseWithCovariance", "Pose pose\nfloat64[36] covariance"),
    ("geometry_msgs/msg/Twist", "Vector3 linear\nVector3 angular"),
    ("geometry_msgs/msg/TwistWithCovariance", "Twist twist\nfloat64[36] covariance"),
    ("geometry_msgs/msg/Transform", "Vector3 translation\nQuaternion rotation"),
    ("geometry_msgs/msg/TransformStamped", "std_msgs/Header header\nstring child_frame_id\nTransform transform"),
    ("tf2_msgs/msg/TFMessage", "geometry_msgs/TransformStamped[] transforms"),
    ("rosgraph_msgs/msg/Clock", "builtin_interfaces/Time clock"),
    (
        "nav_msgs/msg/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist",
    ),
    (
        "sensor_msgs/msg/Image",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n\
         uint32 step\nuint8[] data",
    ),
    ("sensor_msgs/msg/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data"),
    (
        "sensor_msgs/msg/RegionOfInterest",
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify",
    ),
    (
        "sensor_msgs/msg/CameraInfo",
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n\
         float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\nRegionOfInterest roi",
    ),
    ("visualization_msgs/msg/UVCoordinate", "float32 u\nfloat32 v"),
    ("visualization_msgs/msg/MeshFile", "string filename\nuint8[] data"),
    (
        "visualization_msgs/msg/Marker",
        "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Pose pose\n\
         geometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\n\
         bool frame_locked\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\n\
         string texture_resource\nsensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\n\
         string text\nstring mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials",
    ),
    ("visualization_msgs/msg/MarkerArray", "Marker[] markers"),
    (
        "ackermann_msgs/msg/AckermannDrive",
        "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\nfloat32 acceleration\nfloat32 jerk",
    ),
    ("ackermann_msgs/msg/AckermannDriveStamped", "std_msgs/Header header\nAckermannDrive drive"),
];
