//! The ego's motion as the controller takes it: speed, acceleration, yaw rate and pose now,
//! and the filter that keeps a wheel-speed reading's noise out of everything derived from it.

/// The ego now: from vehicle/speed and vehicle/state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EgoNow {
    pub t_s: f64,
    pub speed_mps: f64,
    /// Measured longitudinal acceleration.
    pub accel_mps2: f64,
    pub yaw_rate_radps: f64,
    /// Where the ego is, when known (vehicle/state): with the road's map it gives the lane
    /// ahead.
    pub pose: Option<Pose>,
}

/// The ego's speed as the ACC uses it: vehicle/speed carried forward by the measured
/// acceleration and pulled toward each new reading over EGO_SPEED_TAU_S (a complementary
/// filter). A wheel-speed reading's noise would otherwise reach everything the ACC derives
/// from the speed: differenced over a 50 ms frame, a few cm/s of noise become metres per
/// second squared in the lead's estimated acceleration, even with ground truth. Carried by
/// the acceleration it does not lag a braking car. Without an
/// acceleration (no vehicle/state yet) the reading is taken as it is; a jump beyond
/// EGO_SPEED_RESET_MPS (a replay starting over, a reset vehicle) is too.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct EgoSpeedFilter {
    last: Option<(f64, f64)>,
}

/// How long the filter takes to follow a reading (the noise it leaves is about a sixth of a
/// 100 Hz reading's).
const EGO_SPEED_TAU_S: f64 = 0.2;
const EGO_SPEED_RESET_MPS: f64 = 2.0;

impl EgoSpeedFilter {
    /// The speed at `t_s` from the reading `measured_mps` and the acceleration measured since
    /// the last reading, when there is one.
    pub(crate) fn update(&mut self, t_s: f64, measured_mps: f64, accel_mps2: Option<f64>) -> f64 {
        let v = match (self.last, accel_mps2) {
            (Some((t0, v0)), Some(a)) if t_s > t0 => {
                let dt = t_s - t0;
                let predicted = v0 + a * dt;
                if (measured_mps - predicted).abs() > EGO_SPEED_RESET_MPS {
                    measured_mps
                } else {
                    (predicted + dt / (EGO_SPEED_TAU_S + dt) * (measured_mps - predicted)).max(0.0)
                }
            }
            (Some((t0, v0)), Some(_)) if t_s == t0 => v0,
            _ => measured_mps,
        };
        self.last = Some((t_s, v));
        v
    }
}

/// The ego's rear-axle position and heading in the road's frame (vehicle/state's world frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    pub x_m: f64,
    pub y_m: f64,
    pub yaw_rad: f64,
}

impl Pose {
    pub fn of(state: &slipstream_contract::msg::VehicleState) -> Pose {
        let p = state.position_in_world_m;
        Pose { x_m: p[0], y_m: p[1], yaw_rad: state.yaw_in_world_rad }
    }
}
