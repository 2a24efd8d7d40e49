//! Typed messages and their one wire encoding.
//!
//! Every payload on the bus is
//!
//! ```text
//! byte 0      wire version (WIRE_VERSION)
//! byte 1      message kind (MessageKind as u8): a key remapped to the wrong topic is caught
//! header      postcard(Header): seq, stamp_sim_ns, stamp_pub_ns
//! body        postcard(the message struct)
//! ```
//!
//! Decoding is strict: an empty or truncated payload, an unknown version or kind, an invalid
//! enum tag, trailing bytes or a body that fails its own check (a camera frame whose pixel count
//! does not match its size) is a [`DecodeError`] that says what was wrong. Nothing here panics on
//! input. docs/wire-format.md documents the bytes for other languages.

mod acc;
mod any;
mod camera;
mod codec;
mod compressed;
mod ego;
mod image_encoding;
pub mod layout;
mod objects;
mod pixel_error;
mod pixels;
mod road;
mod sim;
mod vehicle;

pub use acc::{AccCommand, AccMode, AccStatus, AccWarning, LeadInfo};
pub use any::{decode_json, peek_kind};
pub use camera::{frame_prefix, CameraFrame, CameraFrameRef, CameraInfo};
pub use codec::{decode, decode_header, encode, encode_into, DecodeError, Stamped};
pub use ego::EgoInfo;
pub use image_encoding::ImageEncoding;
pub use objects::{BoundingBox2d, Detection, Detections, GroundTruthObject, GroundTruthObjects, ObjectClass};
pub use pixel_error::PixelError;
pub use pixels::{check_size as check_frame_size, decode as decode_pixels, encode as encode_pixels, MAX_FRAME_PIXELS};
pub use road::{Curve, LaneEnd, RoadSpec};
pub use sim::{due, SimClock, SimEvent, SimEventKind, SimMode};
pub use vehicle::{ControlCommand, ControlTiming, Speed, VehicleState};
/// Example messages of docs/wire-format.md: the values its byte examples encode (tests of every
/// layer build their messages from them; a decoder of the user's own can check against them).
pub use {acc::example_status, camera::example_info, objects::example_detections, vehicle::example_state};

use serde::{Deserialize, Serialize};

/// Version of the envelope and of every message layout. A decoder refuses any other value.
pub const WIRE_VERSION: u8 = 5;

/// Bytes before the header: version and kind.
pub const PREAMBLE_LEN: usize = 2;

/// Three floats in a right-handed frame (x forward, y left, z up), SI units given by the field.
pub type Vec3 = [f64; 3];

/// The header every message carries.
///
/// `seq` counts messages per publisher from 0 (gaps mean losses), `stamp_sim_ns` is the
/// simulation time the data belongs to (match a frame with a speed by it), `stamp_pub_ns` is
/// the publisher's wall clock (Unix epoch, ns) at publish time (latency = receive - publish).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Header {
    pub seq: u64,
    pub stamp_sim_ns: u64,
    pub stamp_pub_ns: u64,
}

/// Identifies the message type inside a payload (byte 1 of every payload).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum MessageKind {
    Speed = 1,
    VehicleState = 2,
    ControlCommand = 3,
    CameraFrame = 4,
    CameraInfo = 5,
    GroundTruthObjects = 6,
    Detections = 7,
    SimClock = 8,
    SimEvent = 9,
    AccStatus = 10,
    AccCommand = 11,
    RoadMap = 12,
    EgoInfo = 13,
}

impl MessageKind {
    pub const ALL: [MessageKind; 13] = [
        MessageKind::Speed,
        MessageKind::VehicleState,
        MessageKind::ControlCommand,
        MessageKind::CameraFrame,
        MessageKind::CameraInfo,
        MessageKind::GroundTruthObjects,
        MessageKind::Detections,
        MessageKind::SimClock,
        MessageKind::SimEvent,
        MessageKind::AccStatus,
        MessageKind::AccCommand,
        MessageKind::RoadMap,
        MessageKind::EgoInfo,
    ];

    pub fn from_u8(value: u8) -> Option<Self> {
        Self::ALL.into_iter().find(|k| *k as u8 == value)
    }

    /// The type name, as used in docs, errors and the Zenoh encoding schema.
    pub fn name(self) -> &'static str {
        match self {
            MessageKind::Speed => "Speed",
            MessageKind::VehicleState => "VehicleState",
            MessageKind::ControlCommand => "ControlCommand",
            MessageKind::CameraFrame => "CameraFrame",
            MessageKind::CameraInfo => "CameraInfo",
            MessageKind::GroundTruthObjects => "GroundTruthObjects",
            MessageKind::Detections => "Detections",
            MessageKind::SimClock => "SimClock",
            MessageKind::SimEvent => "SimEvent",
            MessageKind::AccStatus => "AccStatus",
            MessageKind::AccCommand => "AccCommand",
            MessageKind::RoadMap => "RoadMap",
            MessageKind::EgoInfo => "EgoInfo",
        }
    }

    /// The Zenoh encoding attached to every sample of this kind:
    /// `application/octet-stream;slipstream/<Name>/v<WIRE_VERSION>`.
    pub fn encoding_schema(self) -> String {
        format!("slipstream/{}/v{}", self.name(), WIRE_VERSION)
    }
}

/// What a decoded message breaks (a size that must agree, a value out of its range), said
/// for the person reading the receiver's log: the field, its value and the rule.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Unsound(pub String);

/// A message type that travels on the bus.
pub trait Message: Serialize + std::fmt::Debug {
    const KIND: MessageKind;

    /// A semantic check run after a successful decode (sizes that must agree, ranges).
    fn check(&self) -> Result<(), Unsound> {
        Ok(())
    }
}

/// Bytes as lowercase hex pairs separated by spaces, 16 per line (the form docs/wire-format.md
/// quotes).
pub fn hex_lines(bytes: &[u8]) -> String {
    bytes
        .chunks(16)
        .map(|c| c.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(" "))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Wall-clock time now, in ns since the Unix epoch (the unit of `Header::stamp_pub_ns`).
pub fn wall_clock_ns() -> u64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0)
}

/// One example value of every message, for docs/wire-format.md, the Python client's tests and
/// round-trip tests. Returns (kind, header, encoded bytes).
pub fn examples() -> Vec<(MessageKind, Vec<u8>)> {
    let h = Header { seq: 7, stamp_sim_ns: 1_250_000_000, stamp_pub_ns: 1_700_000_000_123_456_789 };
    let e = |kind, bytes| (kind, bytes);
    vec![
        e(MessageKind::Speed, encode(&h, &Speed { speed_mps: 27.5 })),
        e(MessageKind::VehicleState, encode(&h, &vehicle::example_state())),
        e(
            MessageKind::ControlCommand,
            encode(
                &h,
                &ControlCommand {
                    throttle: 0.25,
                    brake: 0.0,
                    steer: -0.5,
                    answers_step: Some(125),
                    perception_stamp_pub_ns: Some(1_700_000_000_100_000_000),
                },
            ),
        ),
        e(
            MessageKind::CameraFrame,
            encode(
                &h,
                &CameraFrame { width: 2, height: 1, encoding: ImageEncoding::Rgb8, data: vec![255, 0, 0, 0, 128, 255] },
            ),
        ),
        e(MessageKind::CameraInfo, encode(&h, &camera::example_info())),
        e(MessageKind::GroundTruthObjects, encode(&h, &objects::example_ground_truth())),
        e(MessageKind::Detections, encode(&h, &objects::example_detections())),
        e(
            MessageKind::SimClock,
            encode(&h, &SimClock { step: 125, real_time_factor: 1.0, mode: SimMode::Lockstep, physics_hz: 100.0 }),
        ),
        e(
            MessageKind::SimEvent,
            encode(&h, &SimEvent { kind: SimEventKind::Collision { other_id: 3, relative_speed_mps: 4.5 } }),
        ),
        e(MessageKind::AccStatus, encode(&h, &acc::example_status())),
        e(
            MessageKind::AccCommand,
            encode(&h, &AccCommand { enable: Some(true), set_speed_mps: Some(25.0), time_gap_s: None }),
        ),
        e(
            MessageKind::RoadMap,
            encode(
                &h,
                &RoadSpec {
                    lanes: 3,
                    lane_width_m: 3.5,
                    length_m: 4000.0,
                    curves: vec![Curve { start_m: 300.0, length_m: 350.0, radius_m: 600.0 }],
                    lane_ends: vec![LaneEnd { lane: 0, end_m: 900.0, taper_m: 120.0 }],
                },
            ),
        ),
        e(MessageKind::EgoInfo, encode(&h, &ego::example())),
    ]
}
