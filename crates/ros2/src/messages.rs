//! ROS 2 messages as Rust structs whose serde layout is their CDR layout (field order and
//! types as in [`super::catalog`]), serialized by hiroz-cdr with the 4-byte encapsulation
//! header rmw_zenoh puts first (CDR, little endian).
//!
//! Borrowed byte slices (`Image::data`) let a camera frame go from the bus's payload into the
//! CDR buffer with one copy.

use serde::{Deserialize, Serialize};

use crate::message_error::Ros2Error;

/// CDR, little endian, no options: the encapsulation header of every ROS 2 payload.
pub(crate) const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Serializes `msg` behind the encapsulation header.
pub(crate) fn to_cdr<T: Serialize>(msg: &T, size_hint: usize) -> Result<Vec<u8>, Ros2Error> {
    let mut buf = Vec::with_capacity(size_hint + CDR_LE.len());
    buf.extend_from_slice(&CDR_LE);
    let mut ser = hiroz_cdr::CdrSerializer::<hiroz_cdr::LittleEndian>::new(&mut buf);
    msg.serialize(&mut ser).map_err(|e| Ros2Error::Encode(e.to_string()))?;
    Ok(buf)
}

/// Deserializes a CDR payload (either byte order), refusing a bad header and trailing bytes
/// beyond CDR's 4-byte padding.
pub(crate) fn from_cdr<T: for<'de> Deserialize<'de>>(payload: &[u8]) -> Result<T, Ros2Error> {
    if payload.len() < 4 {
        return Err(Ros2Error::Cdr(format!("{} bytes is shorter than the CDR header", payload.len())));
    }
    let body = &payload[4..];
    let (msg, used) = match payload[..2] {
        [0x00, 0x01] => hiroz_cdr::from_bytes::<T, hiroz_cdr::LittleEndian>(body),
        [0x00, 0x00] => hiroz_cdr::from_bytes::<T, hiroz_cdr::BigEndian>(body),
        _ => return Err(Ros2Error::Cdr(format!("encapsulation {:02x?} is not plain CDR", &payload[..2]))),
    }
    .map_err(|e| Ros2Error::Cdr(format!("CDR does not decode: {e}")))?;
    if body.len() - used > 3 {
        return Err(Ros2Error::Cdr(format!("{} bytes left after the message", body.len() - used)));
    }
    Ok(msg)
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Nanoseconds (of simulation time) as a ROS time; beyond i32 seconds it saturates.
    pub(crate) fn from_ns(ns: u64) -> Time {
        let sec = (ns / 1_000_000_000).min(i32::MAX as u64) as i32;
        Time { sec, nanosec: (ns % 1_000_000_000) as u32 }
    }
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct MultiArrayDimension {
    pub label: String,
    pub size: u32,
    pub stride: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct MultiArrayLayout {
    pub dim: Vec<MultiArrayDimension>,
    pub data_offset: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Float64MultiArray {
    pub layout: MultiArrayLayout,
    pub data: Vec<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

pub(crate) type Point = Vector3;

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Quaternion {
    pub(crate) const IDENTITY: Quaternion = Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 };

    /// From roll, pitch, yaw (rad), applied yaw, then pitch, then roll (ROS's convention).
    pub(crate) fn from_rpy(roll: f64, pitch: f64, yaw: f64) -> Quaternion {
        let (sr, cr) = (roll / 2.0).sin_cos();
        let (sp, cp) = (pitch / 2.0).sin_cos();
        let (sy, cy) = (yaw / 2.0).sin_cos();
        Quaternion {
            x: sr * cp * cy - cr * sp * sy,
            y: cr * sp * cy + sr * cp * sy,
            z: cr * cp * sy - sr * sp * cy,
            w: cr * cp * cy + sr * sp * sy,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

/// A 6x6 covariance, row major (serde has no arrays of 36).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Covariance(pub [f64; 36]);

impl Serialize for Covariance {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Covariance;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance, A::Error> {
                let mut out = [0.0; 36];
                for (i, v) in out.iter_mut().enumerate() {
                    *v = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance(out))
            }
        }
        d.deserialize_tuple(36, Visit)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Covariance,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Covariance,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct Clock {
    pub clock: Time,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// sensor_msgs/msg/Image with its pixels borrowed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Image<'a> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub encoding: &'a str,
    pub is_bigendian: u8,
    pub step: u32,
    #[serde(with = "serde_bytes")]
    pub data: &'a [u8],
}

/// sensor_msgs/msg/CompressedImage with its bytes borrowed.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct CompressedImage<'a> {
    pub header: Header,
    pub format: &'a str,
    #[serde(with = "serde_bytes")]
    pub data: &'a [u8],
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct RegionOfInterest {
    pub x_offset: u32,
    pub y_offset: u32,
    pub height: u32,
    pub width: u32,
    pub do_rectify: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct CameraInfo {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub distortion_model: String,
    pub d: Vec<f64>,
    pub k: [f64; 9],
    pub r: [f64; 9],
    pub p: [f64; 12],
    pub binning_x: u32,
    pub binning_y: u32,
    pub roi: RegionOfInterest,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct UvCoordinate {
    pub u: f32,
    pub v: f32,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct MeshFile {
    pub filename: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// sensor_msgs/msg/CompressedImage, owned (an empty texture inside a Marker).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct OwnedCompressedImage {
    pub header: Header,
    pub format: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// visualization_msgs/msg/Marker.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    /// CUBE = 1, TEXT_VIEW_FACING = 9.
    #[serde(rename = "type")]
    pub kind: i32,
    /// ADD = 0, DELETEALL = 3.
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRgba,
    pub lifetime: Time,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: OwnedCompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct MarkerArray {
    pub markers: Vec<Marker>,
}

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct AckermannDrive {
    pub steering_angle: f32,
    pub steering_angle_velocity: f32,
    pub speed: f32,
    pub acceleration: f32,
    pub jerk: f32,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub(crate) struct AckermannDriveStamped {
    pub header: Header,
    pub drive: AckermannDrive,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_is_header_then_two_aligned_words() {
        let cdr = to_cdr(&Clock { clock: Time { sec: 12, nanosec: 500 } }, 8).unwrap();
        assert_eq!(cdr, [0, 1, 0, 0, 12, 0, 0, 0, 0xf4, 1, 0, 0]);
    }

    #[test]
    fn doubles_align_to_eight_after_the_encapsulation_header() {
        // Header (stamp 8 bytes + "a\0" with its length 4 = 14) then a float64 at offset 16.
        let t = TransformStamped {
            header: Header { stamp: Time::default(), frame_id: "a".into() },
            child_frame_id: String::new(),
            transform: Transform { translation: Vector3 { x: 1.0, y: 0.0, z: 0.0 }, rotation: Quaternion::IDENTITY },
        };
        let cdr = to_cdr(&t, 0).unwrap();
        // child_frame_id: length 1 at 16..20 and its NUL at 20; x at 24 (8-aligned body offset).
        assert_eq!(&cdr[4 + 16..4 + 21], &[1, 0, 0, 0, 0]);
        assert_eq!(&cdr[4 + 24..4 + 32], &1.0f64.to_le_bytes());
    }

    #[test]
    fn commands_round_trip_and_garbage_is_refused() {
        let cmd = AckermannDriveStamped {
            header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "ego".into() },
            drive: AckermannDrive { steering_angle: 0.1, speed: 20.0, acceleration: -1.5, ..Default::default() },
        };
        let cdr = to_cdr(&cmd, 64).unwrap();
        assert_eq!(from_cdr::<AckermannDriveStamped>(&cdr).unwrap(), cmd);
        assert!(from_cdr::<AckermannDriveStamped>(&cdr[..cdr.len() - 6]).is_err());
        assert!(from_cdr::<AckermannDriveStamped>(&[0, 1]).is_err());
        let mut extra = cdr.clone();
        extra.extend_from_slice(&[0; 16]);
        assert!(from_cdr::<AckermannDriveStamped>(&extra).is_err());
    }

    #[test]
    fn yaw_quaternion() {
        let q = Quaternion::from_rpy(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!((q.z - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-12 && (q.w - q.z).abs() < 1e-12);
    }
}
