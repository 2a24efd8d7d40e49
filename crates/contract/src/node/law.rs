//! What a control law of the user's own is given and gives back (`controller::run` calls it
//! once per step): the ego, the vehicles ahead, the driver's settings, and a decision. A file
//! of its own so that the controller and what it reads share the vocabulary without a circle.

use crate::msg::EgoInfo;

/// The time gap before sim/ego or acc/command gives one, s (slipstream-acc's default).
const DEFAULT_TIME_GAP_S: f64 = 1.8;

/// The ego at the step answered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ego {
    pub t_s: f64,
    pub step: u64,
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub yaw_rate_radps: f64,
}

/// A vehicle ahead: the gap from the ego's front bumper to its rear, its centre's lateral
/// offset (positive left) and its speed relative to the ego's (negative: closing in).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ahead {
    pub id: u32,
    pub gap_m: f64,
    pub lateral_m: f64,
    pub relative_speed_mps: f64,
    pub brake_lights: bool,
}

/// The driver's settings (sim/ego at the start, acc/command after) and the vehicle sim/ego
/// declares (None until it came).
#[derive(Debug, Clone, PartialEq)]
pub struct DriverSettings {
    pub set_speed_mps: f64,
    pub time_gap_s: f64,
    pub enabled: bool,
    pub vehicle: Option<EgoInfo>,
}

impl Default for DriverSettings {
    fn default() -> Self {
        DriverSettings { set_speed_mps: 0.0, time_gap_s: DEFAULT_TIME_GAP_S, enabled: true, vehicle: None }
    }
}

/// What `control` may return instead of a bare acceleration: the lead it follows (for
/// acc/status and the judge's lead figures) and whether this is an emergency brake.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    pub accel_mps2: f64,
    pub lead: Option<Ahead>,
    pub emergency: bool,
}

impl From<f64> for Decision {
    fn from(accel_mps2: f64) -> Self {
        Decision { accel_mps2, lead: None, emergency: false }
    }
}
