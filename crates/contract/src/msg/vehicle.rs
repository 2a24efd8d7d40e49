//! Ego vehicle messages: speed, full state and the control command that drives it.

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind, Unsound, Vec3};

/// vehicle/speed: the ego's speed over ground, the 100 Hz hot path.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Speed {
    pub speed_mps: f64,
}

impl Message for Speed {
    const KIND: MessageKind = MessageKind::Speed;
}

/// vehicle/state: pose, motion and the control the simulator applied in this step.
///
/// World frame: x east/along the road, y left, z up, origin at the road start. Body frame:
/// x forward, y left, z up, origin at the rear-axle centre on the ground.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VehicleState {
    /// Simulation step this state was taken at.
    pub step: u64,
    pub position_in_world_m: Vec3,
    /// Heading about z, counter-clockwise from world x.
    pub yaw_in_world_rad: f64,
    pub pitch_rad: f64,
    pub roll_rad: f64,
    pub velocity_in_world_mps: Vec3,
    /// Acceleration in the body frame (longitudinal, lateral, vertical).
    pub acceleration_in_body_mps2: Vec3,
    pub yaw_rate_radps: f64,
    pub speed_mps: f64,
    /// Index of the lane the vehicle's centre is in (0 = rightmost), -1 when off the road.
    pub lane: i32,
    /// The control command in effect during this step.
    pub applied: ControlCommand,
    /// When that command was published and when the simulator first applied it; None while
    /// no command is in effect (before the first, or braking after commands stopped).
    pub control_timing: Option<ControlTiming>,
}

/// The last hop of the loop: a command's publish time and the time the simulator first
/// applied it, both wall clock (ns since the Unix epoch).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ControlTiming {
    /// The command's header.stamp_pub_ns.
    pub command_stamp_pub_ns: u64,
    /// When the simulator first stepped the physics with it.
    pub applied_ns: u64,
}

impl Message for VehicleState {
    const KIND: MessageKind = MessageKind::VehicleState;
}

/// vehicle/control: what a controller asks of the ego vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ControlCommand {
    /// 0..1
    pub throttle: f32,
    /// 0..1
    pub brake: f32,
    /// -1 (full right) .. 1 (full left)
    pub steer: f32,
    /// The simulation step this command answers (lockstep waits for it); None when not stepped.
    pub answers_step: Option<u64>,
    /// header.stamp_pub_ns of the newest perception message (perception/objects, or objects)
    /// this command was computed from; None when it used none. With Detections'
    /// frame_stamp_pub_ns and VehicleState's control_timing it traces the loop hop by hop.
    pub perception_stamp_pub_ns: Option<u64>,
}

impl ControlCommand {
    pub const NEUTRAL: ControlCommand =
        ControlCommand { throttle: 0.0, brake: 0.0, steer: 0.0, answers_step: None, perception_stamp_pub_ns: None };
}

impl Message for ControlCommand {
    const KIND: MessageKind = MessageKind::ControlCommand;

    fn check(&self) -> Result<(), Unsound> {
        let in_range = |v: f32, lo: f32, hi: f32| v.is_finite() && (lo..=hi).contains(&v);
        if !in_range(self.throttle, 0.0, 1.0) {
            return Err(Unsound(format!("throttle {} is outside 0..1", self.throttle)));
        }
        if !in_range(self.brake, 0.0, 1.0) {
            return Err(Unsound(format!("brake {} is outside 0..1", self.brake)));
        }
        if !in_range(self.steer, -1.0, 1.0) {
            return Err(Unsound(format!("steer {} is outside -1..1", self.steer)));
        }
        Ok(())
    }
}

/// The VehicleState of docs/wire-format.md's byte example.
pub fn example_state() -> VehicleState {
    VehicleState {
        step: 125,
        position_in_world_m: [31.25, -1.75, 0.0],
        yaw_in_world_rad: 0.0,
        pitch_rad: 0.0,
        roll_rad: 0.0,
        velocity_in_world_mps: [27.5, 0.0, 0.0],
        acceleration_in_body_mps2: [0.5, 0.0, 0.0],
        yaw_rate_radps: 0.0,
        speed_mps: 27.5,
        lane: 1,
        applied: ControlCommand {
            throttle: 0.25,
            brake: 0.0,
            steer: 0.0,
            answers_step: Some(124),
            perception_stamp_pub_ns: Some(1_700_000_000_100_000_000),
        },
        control_timing: Some(ControlTiming {
            command_stamp_pub_ns: 1_700_000_000_110_000_000,
            applied_ns: 1_700_000_000_120_000_000,
        }),
    }
}
