//! How the simulator runs (as opposed to what it simulates, which is the scenario): clock mode,
//! rates, camera, lockstep and the policy when control commands stop. config/sim.json5
//! documents every key and holds the defaults; a settings file of one's own needs only the keys
//! it changes. Command-line flags override the common ones.

use std::path::Path;

use serde::Deserialize;

use crate::config::{parse_layered, read_config, ConfigError};
use crate::msg::{CameraInfo, ImageEncoding, SimMode};

/// The settings file shipped with the project; its values are the built-in defaults.
pub const DEFAULT_SIM_CONFIG: &str = include_str!("../../config/sim.json5");
pub const DEFAULT_SIM_CONFIG_PATH: &str = "config/sim.json5";

const FIX: &str = "see the comments in config/sim.json5 for every key and its allowed values";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    Realtime,
    Fast,
    Lockstep,
}

impl From<Mode> for SimMode {
    fn from(m: Mode) -> SimMode {
        match m {
            Mode::Realtime => SimMode::Realtime,
            Mode::Fast => SimMode::Fast,
            Mode::Lockstep => SimMode::Lockstep,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimSettings {
    pub mode: Mode,
    /// Physics steps per simulated second.
    pub physics_hz: u32,
    /// In realtime mode: simulated seconds per wall-clock second (1 = real time).
    pub realtime_factor: f64,
    pub rates_hz: Rates,
    pub camera: CameraSpec,
    pub lockstep: LockstepSpec,
    pub control: ControlPolicy,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rates {
    pub speed: f64,
    pub state: f64,
    pub clock: f64,
    /// Camera frames; ground truth (objects) goes with every frame.
    pub camera: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub width: u32,
    pub height: u32,
    pub horizontal_fov_deg: f64,
    /// Camera position in the ego body frame (origin: rear-axle centre on the ground).
    pub mount_position_m: [f64; 3],
    /// Roll, pitch (positive looks down), yaw relative to the body.
    pub mount_roll_pitch_yaw_deg: [f64; 3],
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum OnTimeout {
    Continue,
    Stop,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LockstepSpec {
    /// Nodes whose vehicle/control answer each step waits for; the first one's command drives.
    pub wait_for: Vec<String>,
    /// How long one step waits for the answers (wall clock).
    pub step_timeout_ms: u64,
    pub on_timeout: OnTimeout,
    /// How long to wait at the start for the awaited nodes to appear.
    pub start_timeout_ms: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BeforeFirst {
    /// Hold the scenario's start speed in lane.
    Cruise,
    /// Brake as after a timeout.
    Brake,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlPolicy {
    /// Keep applying the last command this long (simulated time) after it arrived...
    pub hold_ms: u64,
    /// ...then brake this hard (0..1) until a command arrives.
    pub timeout_brake: f32,
    /// A command whose header stamp_sim_ns is further behind the simulation than this (ms of
    /// simulated time) answered a state long gone (e.g. it waited in a queue while a link was
    /// down): counted, logged, not applied. 0: no limit. Stamp 0 means unstamped: applied.
    pub max_age_ms: u64,
    pub before_first: BeforeFirst,
}

impl Default for SimSettings {
    fn default() -> Self {
        // The shipped file is the single source of the defaults; a test keeps it parseable.
        SimSettings::parse(DEFAULT_SIM_CONFIG, DEFAULT_SIM_CONFIG_PATH).expect("config/sim.json5 is valid")
    }
}

impl SimSettings {
    /// Settings from a file, or the built-in defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<SimSettings, ConfigError> {
        let Some(path) = path else { return Ok(SimSettings::default()) };
        let (text, origin) = read_config(path)?;
        SimSettings::parse(&text, &origin)
    }

    /// Parses settings text laid over the defaults: a file needs only the keys it changes.
    pub fn parse(text: &str, origin: &str) -> Result<SimSettings, ConfigError> {
        let s: SimSettings = parse_layered(DEFAULT_SIM_CONFIG, DEFAULT_SIM_CONFIG_PATH, text, origin, FIX)?;
        s.check().map_err(|(key, problem, fix)| ConfigError::new(origin, key, problem, fix))?;
        Ok(s)
    }

    /// Ranges and relations serde cannot check.
    pub fn check(&self) -> Result<(), (String, String, String)> {
        let err = |key: &str, problem: String, fix: &str| Err((key.to_string(), problem, fix.to_string()));
        if !(10..=2000).contains(&self.physics_hz) {
            return err("physics_hz", format!("{} Hz", self.physics_hz), "use 10 to 2000 Hz");
        }
        if !(self.realtime_factor > 0.0 && self.realtime_factor <= 100.0) {
            return err("realtime_factor", format!("{}", self.realtime_factor), "use a factor in (0, 100]");
        }
        let r = &self.rates_hz;
        for (key, v) in [
            ("rates_hz.speed", r.speed),
            ("rates_hz.state", r.state),
            ("rates_hz.clock", r.clock),
            ("rates_hz.camera", r.camera),
        ] {
            if !(v > 0.0 && v <= self.physics_hz as f64) {
                return err(key, format!("{v} Hz"), &format!("use a rate in (0, physics_hz = {}]", self.physics_hz));
            }
        }
        let c = &self.camera;
        if !(16..=4096).contains(&c.width) || !(16..=4096).contains(&c.height) {
            return err("camera", format!("{}x{}", c.width, c.height), "use 16 to 4096 pixels a side");
        }
        if !(10.0..=170.0).contains(&c.horizontal_fov_deg) {
            return err("camera.horizontal_fov_deg", format!("{}", c.horizontal_fov_deg), "use 10 to 170 degrees");
        }
        if c.mount_position_m[2] <= 0.1 {
            return err("camera.mount_position_m", format!("{:?}", c.mount_position_m), "mount the camera above 0.1 m");
        }
        if self.mode == Mode::Lockstep && self.lockstep.wait_for.is_empty() {
            return err(
                "lockstep.wait_for",
                "lockstep with no node to wait for".into(),
                "name the controller node(s), e.g. [\"acc\"]",
            );
        }
        if self.lockstep.step_timeout_ms == 0 {
            return err("lockstep.step_timeout_ms", "0 ms".into(), "give a timeout > 0");
        }
        if !(0.0..=1.0).contains(&self.control.timeout_brake) {
            return err("control.timeout_brake", format!("{}", self.control.timeout_brake), "use 0 to 1");
        }
        Ok(())
    }

    /// The camera as camera/front/info describes it.
    pub fn camera_info(&self, encoding: ImageEncoding) -> CameraInfo {
        let c = &self.camera;
        CameraInfo::pinhole(
            c.width,
            c.height,
            c.horizontal_fov_deg.to_radians(),
            c.mount_position_m,
            c.mount_roll_pitch_yaw_deg.map(f64::to_radians),
            self.rates_hz.camera,
            encoding,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_settings_parse_and_bad_values_name_key_and_fix() {
        let s = SimSettings::default();
        assert_eq!((s.physics_hz, s.rates_hz.camera, s.camera.width), (100, 20.0, 640));
        let bad = DEFAULT_SIM_CONFIG.replace("physics_hz: 100", "physics_hz: 5");
        let e = SimSettings::parse(&bad, "sim.json5").unwrap_err();
        assert_eq!(e.key, "physics_hz");
        let bad = DEFAULT_SIM_CONFIG.replace("mode: \"realtime\"", "mode: \"turbo\"");
        let e = SimSettings::parse(&bad, "sim.json5").unwrap_err();
        assert_eq!(e.key, "mode");
        assert!(e.problem.contains("realtime"), "{e}");
        let partial = SimSettings::parse("{ mode: 'fast', camera: { width: 320 } }", "mine.json5").unwrap();
        assert_eq!((partial.mode, partial.camera.width, partial.camera.height), (Mode::Fast, 320, 480));
        let e = SimSettings::parse("{ camera: { widht: 320 } }", "mine.json5").unwrap_err();
        assert_eq!((e.origin.as_str(), e.key.as_str()), ("mine.json5", "camera.widht"));
        assert!(e.problem.contains("unknown field `widht`"), "{e}");
    }
}
