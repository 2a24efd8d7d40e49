//! The loop's messages as ROS 2 messages: pure functions, no I/O.
//!
//! Every `header.stamp` is simulation time (so ROS nodes with `use_sim_time` line up with
//! /clock, lockstep included). Frames, prefixed by the vehicle's namespace when it has one:
//!
//! ```text
//! world                          the simulator's world frame (x east along the road, z up)
//!  `- <ns/>ego                   the ego's body: x forward, y left, z up, origin at its centre
//!      `- <ns/>camera_front      the camera's mount: position and roll/pitch/yaw from camera info
//!          `- <ns/>camera_front_optical   ROS's optical convention: z forward, x right, y down
//! ```

use super::messages::{
    CameraInfo as RosCameraInfo, Clock, ColorRgba, CompressedImage, Covariance, Float64MultiArray, Header, Image,
    Marker, MarkerArray, MultiArrayDimension, MultiArrayLayout, Odometry, Pose, PoseWithCovariance, Quaternion,
    RegionOfInterest, Time, Transform, TransformStamped, Twist, TwistWithCovariance, Vector3,
};
use slipstream_contract::msg::{
    AccMode, AccStatus, CameraFrameRef, CameraInfo, Detections, GroundTruthObjects, ImageEncoding, ObjectClass,
    VehicleState,
};
use slipstream_model::vehicle::VehicleParams;

/// The frame names of one vehicle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Frames {
    prefix: String,
}

impl Frames {
    /// Frames under the bus namespace `ns` (none when empty): `car1/ego`, `car1/camera_front`.
    pub(crate) fn new(ns: &str) -> Frames {
        let ns = ns.trim_matches('/');
        Frames { prefix: if ns.is_empty() { String::new() } else { format!("{ns}/") } }
    }

    pub(crate) fn world(&self) -> String {
        "world".into()
    }

    pub(crate) fn ego(&self) -> String {
        format!("{}ego", self.prefix)
    }

    /// A camera's mount frame (`camera_front`) and its optical frame.
    pub(crate) fn camera(&self, camera: &str) -> (String, String) {
        (format!("{}camera_{camera}", self.prefix), format!("{}camera_{camera}_optical", self.prefix))
    }
}

fn header(stamp_sim_ns: u64, frame_id: String) -> Header {
    Header { stamp: Time::from_ns(stamp_sim_ns), frame_id }
}

/// A frame as ROS carries it, pixels borrowed: raw RGB as Image (`rgb8`), JPEG and PNG as
/// CompressedImage, never re-encoded. LZ4 is no ROS image format: the caller decodes it to
/// raw first (translate.rs); given one, it is labelled "lz4", which no ROS tool reads.
#[derive(Debug)]
pub(crate) enum RosImage<'a> {
    Raw(Image<'a>),
    Compressed(CompressedImage<'a>),
}

pub(crate) fn image<'a>(stamp_sim_ns: u64, frame_id: String, frame: &CameraFrameRef<'a>) -> RosImage<'a> {
    let header = header(stamp_sim_ns, frame_id);
    match frame.encoding {
        ImageEncoding::Rgb8 => RosImage::Raw(Image {
            header,
            height: frame.height,
            width: frame.width,
            encoding: "rgb8",
            is_bigendian: 0,
            step: frame.width * 3,
            data: frame.data,
        }),
        ImageEncoding::Jpeg => RosImage::Compressed(CompressedImage { header, format: "jpeg", data: frame.data }),
        ImageEncoding::Png => RosImage::Compressed(CompressedImage { header, format: "png", data: frame.data }),
        ImageEncoding::Lz4 => RosImage::Compressed(CompressedImage { header, format: "lz4", data: frame.data }),
    }
}

/// The pinhole calibration: K, R = identity, P = [K | 0], no distortion (the camera is drawn
/// as an ideal pinhole).
pub(crate) fn camera_info(stamp_sim_ns: u64, optical_frame: String, info: &CameraInfo) -> RosCameraInfo {
    let (fx, fy, cx, cy) = (info.fx_px, info.fy_px, info.cx_px, info.cy_px);
    RosCameraInfo {
        header: header(stamp_sim_ns, optical_frame),
        height: info.height,
        width: info.width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: RegionOfInterest::default(),
    }
}

fn vec3(v: [f64; 3]) -> Vector3 {
    Vector3 { x: v[0], y: v[1], z: v[2] }
}

fn stamped(
    stamp_sim_ns: u64,
    parent: String,
    child: String,
    translation: Vector3,
    rotation: Quaternion,
) -> TransformStamped {
    TransformStamped {
        header: header(stamp_sim_ns, parent),
        child_frame_id: child,
        transform: Transform { translation, rotation },
    }
}

/// ego -> camera mount -> optical frame, for /tf_static.
pub(crate) fn mount_transforms(frames: &Frames, camera: &str, info: &CameraInfo) -> Vec<TransformStamped> {
    let (mount, optical) = frames.camera(camera);
    let [roll, pitch, yaw] = info.mount_roll_pitch_yaw_rad;
    let half_pi = std::f64::consts::FRAC_PI_2;
    vec![
        stamped(
            0,
            frames.ego(),
            mount.clone(),
            vec3(info.mount_position_in_ego_m),
            Quaternion::from_rpy(roll, pitch, yaw),
        ),
        stamped(0, mount, optical, Vector3::default(), Quaternion::from_rpy(-half_pi, 0.0, -half_pi)),
    ]
}

/// world -> ego, for /tf.
pub(crate) fn ego_transform(stamp_sim_ns: u64, frames: &Frames, state: &VehicleState) -> TransformStamped {
    let rotation = Quaternion::from_rpy(state.roll_rad, state.pitch_rad, state.yaw_in_world_rad);
    stamped(stamp_sim_ns, frames.world(), frames.ego(), vec3(state.position_in_world_m), rotation)
}

/// The ego's pose in the world and its twist in its own frame (REP 105's odometry), from the
/// simulator's state: exact, so the covariances are zero.
pub(crate) fn odometry(stamp_sim_ns: u64, frames: &Frames, state: &VehicleState) -> Odometry {
    let (sin, cos) = state.yaw_in_world_rad.sin_cos();
    let [vx, vy, vz] = state.velocity_in_world_mps;
    let linear = Vector3 { x: cos * vx + sin * vy, y: -sin * vx + cos * vy, z: vz };
    let angular = Vector3 { z: state.yaw_rate_radps, ..Vector3::default() };
    let orientation = Quaternion::from_rpy(state.roll_rad, state.pitch_rad, state.yaw_in_world_rad);
    Odometry {
        header: header(stamp_sim_ns, frames.world()),
        child_frame_id: frames.ego(),
        pose: PoseWithCovariance {
            pose: Pose { position: vec3(state.position_in_world_m), orientation },
            covariance: Covariance([0.0; 36]),
        },
        twist: TwistWithCovariance { twist: Twist { linear, angular }, covariance: Covariance([0.0; 36]) },
    }
}

pub(crate) fn clock(stamp_sim_ns: u64) -> Clock {
    Clock { clock: Time::from_ns(stamp_sim_ns) }
}

const CUBE: i32 = 1;
const DELETE_ALL: i32 = 3;

fn class_color(class: ObjectClass) -> ColorRgba {
    let (r, g, b) = match class {
        ObjectClass::Car => (0.2, 0.5, 1.0),
        ObjectClass::Van => (0.2, 0.8, 0.8),
        ObjectClass::Truck => (1.0, 0.6, 0.1),
        ObjectClass::Motorcycle => (0.9, 0.2, 0.9),
        ObjectClass::Unknown => (0.7, 0.7, 0.7),
    };
    ColorRgba { r, g, b, a: 0.6 }
}

fn cube(stamp_sim_ns: u64, frame: &str, ns: &str, id: u32, class: ObjectClass, pose: Pose, size: [f64; 3]) -> Marker {
    Marker {
        header: header(stamp_sim_ns, frame.to_string()),
        ns: ns.into(),
        id: id as i32,
        kind: CUBE,
        action: 0,
        pose,
        scale: vec3(size),
        color: class_color(class),
        lifetime: Time::default(),
        frame_locked: false,
        points: Vec::new(),
        colors: Vec::new(),
        texture_resource: String::new(),
        texture: Default::default(),
        uv_coordinates: Vec::new(),
        text: format!("{class:?} #{id}"),
        mesh_resource: String::new(),
        mesh_file: Default::default(),
        mesh_use_embedded_materials: false,
    }
}

/// The array starts with DELETEALL, so each message is the whole set (boxes of vehicles that
/// left do not linger in rviz2).
fn array(stamp_sim_ns: u64, frame: &str, ns: &str, boxes: impl Iterator<Item = Marker>) -> MarkerArray {
    let mut clear = cube(
        stamp_sim_ns,
        frame,
        ns,
        0,
        ObjectClass::Unknown,
        Pose { position: Vector3::default(), orientation: Quaternion::IDENTITY },
        [0.0; 3],
    );
    clear.action = DELETE_ALL;
    clear.text.clear();
    MarkerArray { markers: std::iter::once(clear).chain(boxes).collect() }
}

/// Ground truth as boxes in the ego's frame: position, heading and size as simulated.
pub(crate) fn ground_truth_markers(stamp_sim_ns: u64, frames: &Frames, objects: &GroundTruthObjects) -> MarkerArray {
    let ego = frames.ego();
    let boxes = objects.objects.iter().map(|o| {
        let pose =
            Pose { position: vec3(o.position_in_ego_m), orientation: Quaternion::from_rpy(0.0, 0.0, o.yaw_in_ego_rad) };
        cube(stamp_sim_ns, &ego, "ground_truth", o.id, o.class, pose, o.size_m)
    });
    array(stamp_sim_ns, &ego, "ground_truth", boxes)
}

/// Detections as boxes in the ego's frame: the rear at the measured distance, centred on the
/// measured lateral offset, the size of the detected class's typical vehicle.
pub(crate) fn detection_markers(stamp_sim_ns: u64, frames: &Frames, detections: &Detections) -> MarkerArray {
    let ego = frames.ego();
    let boxes = detections.detections.iter().map(|d| {
        let size = VehicleParams::of_class(d.class).size_m;
        let position = Vector3 { x: d.distance_m + size[0] / 2.0, y: d.lateral_offset_m, z: size[2] / 2.0 };
        let pose = Pose { position, orientation: Quaternion::IDENTITY };
        cube(stamp_sim_ns, &ego, "perception", d.track_id, d.class, pose, size)
    });
    array(stamp_sim_ns, &ego, "perception", boxes)
}

/// The ACC status's fields, in the order of [`acc_status`]'s data.
pub(crate) const ACC_STATUS_FIELDS: [&str; 10] = [
    "mode",
    "set_speed_mps",
    "time_gap_s",
    "target_accel_mps2",
    "lead_id",
    "gap_m",
    "desired_gap_m",
    "relative_speed_mps",
    "ttc_s",
    "warnings",
];

/// acc/status as numbers a plot takes: mode 0 off, 1 speed, 2 follow, 3 stale, 4 emergency;
/// the lead's fields NaN without a lead (ttc NaN when not closing in); warnings counted. The
/// layout's one dimension is labelled with the field names, comma-separated.
pub(crate) fn acc_status(status: &AccStatus) -> Float64MultiArray {
    let mode = match status.mode {
        AccMode::Off => 0.0,
        AccMode::Speed => 1.0,
        AccMode::Follow => 2.0,
        AccMode::Stale => 3.0,
        AccMode::Emergency => 4.0,
    };
    let lead = status.lead;
    let data = vec![
        mode,
        status.set_speed_mps,
        status.time_gap_s,
        status.target_accel_mps2,
        lead.map_or(f64::NAN, |l| f64::from(l.id)),
        lead.map_or(f64::NAN, |l| l.gap_m),
        lead.map_or(f64::NAN, |l| l.desired_gap_m),
        lead.map_or(f64::NAN, |l| l.relative_speed_mps),
        lead.and_then(|l| l.ttc_s).unwrap_or(f64::NAN),
        status.warnings.len() as f64,
    ];
    let n = data.len() as u32;
    Float64MultiArray {
        layout: MultiArrayLayout {
            dim: vec![MultiArrayDimension { label: ACC_STATUS_FIELDS.join(","), size: n, stride: n }],
            data_offset: 0,
        },
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg;

    #[test]
    fn frames_follow_the_namespace() {
        assert_eq!(Frames::new("").ego(), "ego");
        assert_eq!(Frames::new("car1").camera("front").1, "car1/camera_front_optical");
    }

    #[test]
    fn camera_info_has_the_pinhole_matrices() {
        let info = msg::example_info();
        let ros = camera_info(5, "cam".into(), &info);
        assert_eq!((ros.k[0], ros.k[2], ros.k[5], ros.k[8]), (info.fx_px, info.cx_px, info.cy_px, 1.0));
        assert_eq!((ros.p[0], ros.p[3], ros.p[10]), (info.fx_px, 0.0, 1.0));
        assert_eq!((ros.width, ros.height), (info.width, info.height));
    }

    #[test]
    fn odometry_twist_is_in_the_body_frame() {
        let mut s = msg::example_state();
        s.yaw_in_world_rad = std::f64::consts::FRAC_PI_2;
        s.velocity_in_world_mps = [0.0, 10.0, 0.0];
        let o = odometry(0, &Frames::new(""), &s);
        assert!((o.twist.twist.linear.x - 10.0).abs() < 1e-9 && o.twist.twist.linear.y.abs() < 1e-9);
        assert_eq!(o.pose.pose.position.x, s.position_in_world_m[0]);
    }

    #[test]
    fn acc_status_is_labelled_and_nan_without_a_lead() {
        let mut s = msg::example_status();
        let a = acc_status(&s);
        assert_eq!(a.data.len(), ACC_STATUS_FIELDS.len());
        assert_eq!((a.data[0], a.data[5]), (2.0, 27.75));
        s.lead = None;
        assert!(acc_status(&s).data[5].is_nan());
    }

    #[test]
    fn optical_frame_looks_down_the_body_x_axis() {
        // The optical z axis (0,0,1) rotated into the mount frame must be the body's x.
        let q = &mount_transforms(&Frames::new(""), "front", &msg::example_info())[1].transform.rotation;
        let (x, y, z, w) = (q.x, q.y, q.z, q.w);
        let zx = 2.0 * (x * z + w * y);
        let zy = 2.0 * (y * z - w * x);
        assert!((zx - 1.0).abs() < 1e-9 && zy.abs() < 1e-9, "{zx} {zy}");
    }
}
