//! ROS 2 commands into the loop: an `ackermann_msgs/msg/AckermannDriveStamped` from one ROS
//! node becomes vehicle/control, so a ROS 2 controller can drive the ego with slipstream's
//! ACC turned off.
//!
//! The command is read as Ackermann drivers read it: `speed` is the speed to reach (m/s,
//! forward), `acceleration` the largest rate to reach it with, either way (0: the comfort
//! limits), `steering_angle` the front wheels' angle (rad, left positive).
//! `steering_angle_velocity` and `jerk` are not used. Each vehicle/speed message turns the
//! latest command into throttle and brake through the shared vehicle model, as the ACC does.
//!
//! A command with a NaN, an infinity or a value out of range is refused, and so is one from
//! a second publisher while the first is still sending; refusals are counted and logged at
//! most once a second, and never applied. A command older than [`STALE_AFTER_NS`] is no longer
//! applied: the bridge stops sending, and the simulator's own watchdog (hold, then brake)
//! takes over, as when the ACC dies.

use super::messages::AckermannDrive;
use slipstream_contract::msg::ControlCommand;
use slipstream_model::vehicle::{actuate_acceleration, VehicleParams};

/// A command older than this is not applied (0.5 s: five missed commands of a 10 Hz node).
pub(crate) const STALE_AFTER_NS: u64 = 500_000_000;
/// Fastest speed a command may ask for.
pub(crate) const MAX_SPEED_MPS: f32 = 70.0;
/// Largest acceleration a command may ask for, either way.
pub(crate) const MAX_ACCEL_MPS2: f32 = 10.0;
/// Limits used when a command gives acceleration 0: ISO 15622's comfort figures.
pub(crate) const DEFAULT_ACCEL_MPS2: f64 = 2.0;
pub(crate) const DEFAULT_DECEL_MPS2: f64 = 3.5;
/// Speed error to acceleration (1/s): 1 m/s short asks 0.8 m/s2, within the limits.
pub(crate) const SPEED_GAIN_PER_S: f64 = 0.8;

/// Why a command is refused: a `Copy` value with the figure that ruled it out, said only when
/// counted and logged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Refusal {
    /// A second publisher (its gid) while the first is still sending.
    SecondPublisher([u8; 16]),
    /// A field that is NaN or infinite.
    NotFinite(&'static str, f32),
    /// A speed outside 0..[`MAX_SPEED_MPS`] (no reverse).
    Speed(f32),
    /// An acceleration beyond [`MAX_ACCEL_MPS2`] either way.
    Acceleration(f32),
    /// A steering angle beyond the vehicle's (angle, the vehicle's largest).
    Steering(f32, f32),
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refusal::SecondPublisher(gid) => {
                write!(f, "a second publisher (gid {}) while the first is sending", hex(gid))
            }
            Refusal::NotFinite(name, v) => write!(f, "{name} is {v}"),
            Refusal::Speed(v) => write!(f, "speed {v} m/s is outside 0..{MAX_SPEED_MPS} (no reverse)"),
            Refusal::Acceleration(v) => write!(f, "acceleration {v} m/s2 is beyond {MAX_ACCEL_MPS2}"),
            Refusal::Steering(v, max) => write!(f, "steering angle {v} rad is beyond the vehicle's {max}"),
        }
    }
}

/// What happened to the commands so far.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CommandStats {
    pub accepted: u64,
    pub refused: u64,
    /// Control messages sent on the bus.
    pub applied: u64,
    pub last_refusal: Option<String>,
}

/// The one publisher whose commands count, and its latest command.
#[derive(Debug, Default)]
pub(crate) struct CommandGate {
    owner: Option<[u8; 16]>,
    latest: Option<(AckermannDrive, u64)>,
    pub stats: CommandStats,
    last_log_ns: u64,
    refused_since_log: u64,
}

impl CommandGate {
    /// Takes a command from publisher `gid` received at `now_ns`, or refuses it with why.
    pub(crate) fn offer(
        &mut self,
        gid: [u8; 16],
        now_ns: u64,
        drive: &AckermannDrive,
        params: &VehicleParams,
    ) -> Result<(), Refusal> {
        let verdict = self.judge(gid, now_ns, drive, params);
        match &verdict {
            Ok(()) => {
                self.owner = Some(gid);
                self.latest = Some((*drive, now_ns));
                self.stats.accepted += 1;
            }
            Err(why) => self.refuse(now_ns, why),
        }
        verdict
    }

    /// Counts a refused command, logging why at most once a second.
    pub(crate) fn refuse(&mut self, now_ns: u64, why: &dyn std::fmt::Display) {
        self.stats.refused += 1;
        self.refused_since_log += 1;
        self.stats.last_refusal = Some(why.to_string());
        if now_ns.saturating_sub(self.last_log_ns) >= 1_000_000_000 {
            tracing::warn!(refused = self.refused_since_log, "ROS 2 command refused: {why}");
            self.last_log_ns = now_ns;
            self.refused_since_log = 0;
        }
    }

    fn judge(&self, gid: [u8; 16], now_ns: u64, d: &AckermannDrive, params: &VehicleParams) -> Result<(), Refusal> {
        if let (Some(owner), Some((_, at))) = (self.owner, self.latest) {
            if owner != gid && now_ns.saturating_sub(at) < STALE_AFTER_NS {
                return Err(Refusal::SecondPublisher(gid));
            }
        }
        let fields = [
            ("steering_angle", d.steering_angle),
            ("steering_angle_velocity", d.steering_angle_velocity),
            ("speed", d.speed),
            ("acceleration", d.acceleration),
            ("jerk", d.jerk),
        ];
        if let Some((name, v)) = fields.iter().find(|(_, v)| !v.is_finite()) {
            return Err(Refusal::NotFinite(name, *v));
        }
        if !(0.0..=MAX_SPEED_MPS).contains(&d.speed) {
            return Err(Refusal::Speed(d.speed));
        }
        if d.acceleration.abs() > MAX_ACCEL_MPS2 {
            return Err(Refusal::Acceleration(d.acceleration));
        }
        let max_steer = params.max_steer_rad as f32;
        if d.steering_angle.abs() > max_steer {
            return Err(Refusal::Steering(d.steering_angle, max_steer));
        }
        Ok(())
    }

    /// The newest command taken, fresh or not.
    pub(crate) fn latest(&self) -> Option<AckermannDrive> {
        self.latest.map(|(d, _)| d)
    }

    /// The command to apply at `now_ns` at the ego's `speed_mps`, or None when there is no
    /// fresh command.
    pub(crate) fn control(&self, now_ns: u64, speed_mps: f64, params: &VehicleParams) -> Option<ControlCommand> {
        let (d, at) = self.latest?;
        if now_ns.saturating_sub(at) >= STALE_AFTER_NS {
            return None;
        }
        Some(control(&d, speed_mps, params))
    }
}

/// The acceleration a command asks for at `speed_mps`: toward its speed, within its own limit
/// (or the comfort limits when it gives none).
pub(crate) fn acceleration(d: &AckermannDrive, speed_mps: f64) -> f64 {
    let limit = f64::from(d.acceleration.abs());
    let (up, down) = if limit > 0.0 { (limit, limit) } else { (DEFAULT_ACCEL_MPS2, DEFAULT_DECEL_MPS2) };
    (SPEED_GAIN_PER_S * (f64::from(d.speed) - speed_mps)).clamp(-down, up)
}

/// Throttle, brake and steer that take the ego from `speed_mps` toward the command's speed.
pub(crate) fn control(d: &AckermannDrive, speed_mps: f64, params: &VehicleParams) -> ControlCommand {
    let accel = acceleration(d, speed_mps);
    let (throttle, brake) = if d.speed == 0.0 && speed_mps < 0.5 {
        (0.0, 0.3) // hold still
    } else {
        actuate_acceleration(params, speed_mps, accel)
    };
    ControlCommand {
        throttle: throttle as f32,
        brake: brake as f32,
        steer: (f64::from(d.steering_angle) / params.max_steer_rad).clamp(-1.0, 1.0) as f32,
        answers_step: None,
        perception_stamp_pub_ns: None,
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::Message as _;

    const CAR: VehicleParams = VehicleParams::CAR;

    fn drive(speed: f32) -> AckermannDrive {
        AckermannDrive { speed, ..Default::default() }
    }

    #[test]
    fn a_fresh_command_drives_toward_its_speed_and_goes_stale() {
        let mut gate = CommandGate::default();
        gate.offer([1; 16], 0, &drive(20.0), &CAR).unwrap();
        let faster = gate.control(100_000_000, 10.0, &CAR).unwrap();
        assert!(faster.throttle > 0.0 && faster.brake == 0.0, "{faster:?}");
        let slower = gate.control(100_000_000, 30.0, &CAR).unwrap();
        assert!(slower.brake > 0.0 && slower.throttle == 0.0, "{slower:?}");
        assert!(slower.check().is_ok());
        assert_eq!(gate.control(STALE_AFTER_NS, 10.0, &CAR), None);
    }

    #[test]
    fn bad_values_and_a_second_publisher_are_refused_and_never_applied() {
        let mut gate = CommandGate::default();
        for bad in [
            AckermannDrive { speed: f32::NAN, ..Default::default() },
            AckermannDrive { steering_angle: 2.0, ..drive(10.0) },
            AckermannDrive { acceleration: 50.0, ..drive(10.0) },
            drive(-3.0),
            AckermannDrive { jerk: f32::INFINITY, ..drive(10.0) },
        ] {
            assert!(gate.offer([1; 16], 0, &bad, &CAR).is_err(), "{bad:?}");
        }
        assert_eq!(gate.control(0, 10.0, &CAR), None);
        gate.offer([1; 16], 0, &drive(10.0), &CAR).unwrap();
        let err = gate.offer([2; 16], 1, &drive(30.0), &CAR).unwrap_err().to_string();
        assert!(err.contains("second publisher"), "{err}");
        // The first publisher's command still holds.
        assert!(gate.control(2, 20.0, &CAR).unwrap().brake > 0.0);
        // Once the first has gone quiet, another may take over.
        gate.offer([2; 16], STALE_AFTER_NS + 1, &drive(30.0), &CAR).unwrap();
        assert_eq!((gate.stats.accepted, gate.stats.refused), (2, 6));
    }

    #[test]
    fn steering_maps_onto_the_vehicles_range() {
        let c = control(&AckermannDrive { steering_angle: CAR.max_steer_rad as f32 / 2.0, ..drive(10.0) }, 10.0, &CAR);
        assert!((c.steer - 0.5).abs() < 1e-6);
    }
}
