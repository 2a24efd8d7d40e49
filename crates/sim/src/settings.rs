//! How the simulator runs (as opposed to what it simulates, which is the scenario): clock mode,
//! rates, camera, lockstep and the policy when control commands stop. config/sim.json5
//! documents every key and holds the defaults; a settings file of one's own needs only the keys
//! it changes. Command-line flags override the common ones.

use std::path::Path;

use serde::Deserialize;

use slipstream_contract::config::{parse_layered, read_config, ConfigError, Invalid};
use slipstream_contract::msg::{CameraInfo, ImageEncoding, SimMode};

/// The settings file shipped with the project; its values are the built-in defaults.
pub(crate) const DEFAULT_SIM_CONFIG: &str = include_str!("../../../config/sim.json5");
pub(crate) const DEFAULT_SIM_CONFIG_PATH: &str = "config/sim.json5";

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
    /// The long-range camera (camera/narrow), at the front camera's rate and stamps.
    pub narrow_camera: CameraSpec,
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
    /// Only the narrow camera may be turned off.
    #[serde(default = "on")]
    pub enabled: bool,
    pub width: u32,
    pub height: u32,
    pub horizontal_fov_deg: f64,
    /// Camera position in the ego body frame (origin: rear-axle centre on the ground).
    pub mount_position_m: [f64; 3],
    /// Roll, pitch (positive looks down), yaw relative to the body.
    pub mount_roll_pitch_yaw_deg: [f64; 3],
}

fn on() -> bool {
    true
}

impl CameraSpec {
    /// The camera as its info topic describes it.
    pub fn info(&self, rate_hz: f64, encoding: ImageEncoding) -> CameraInfo {
        CameraInfo::pinhole(
            self.width,
            self.height,
            self.horizontal_fov_deg.to_radians(),
            self.mount_position_m,
            self.mount_roll_pitch_yaw_deg.map(f64::to_radians),
            rate_hz,
            encoding,
        )
    }

    fn check(&self, key: &str) -> Result<(), Invalid> {
        let err = |k: &str, problem: String, fix: &str| Invalid::err(format!("{key}{k}"), problem, fix);
        if !(16..=4096).contains(&self.width) || !(16..=4096).contains(&self.height) {
            return err("", format!("{}x{}", self.width, self.height), "use 16 to 4096 pixels a side");
        }
        if !(10.0..=170.0).contains(&self.horizontal_fov_deg) {
            return err(".horizontal_fov_deg", format!("{}", self.horizontal_fov_deg), "use 10 to 170 degrees");
        }
        if self.mount_position_m[2] <= 0.1 {
            return err(".mount_position_m", format!("{:?}", self.mount_position_m), "mount the camera above 0.1 m");
        }
        Ok(())
    }
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
    /// Settings from the file given, else from config/sim.json5 when the working directory
    /// has one, else the built-in defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<SimSettings, ConfigError> {
        let shipped = Path::new(DEFAULT_SIM_CONFIG_PATH);
        let Some(path) = path.or_else(|| shipped.exists().then_some(shipped)) else {
            return Ok(SimSettings::default());
        };
        let (text, origin) = read_config(path)?;
        SimSettings::parse(&text, &origin)
    }

    /// Parses settings text laid over the defaults: a file needs only the keys it changes.
    pub fn parse(text: &str, origin: &str) -> Result<SimSettings, ConfigError> {
        let s: SimSettings = parse_layered(DEFAULT_SIM_CONFIG, DEFAULT_SIM_CONFIG_PATH, text, origin, FIX)?;
        s.check().map_err(|i| i.at(origin))?;
        Ok(s)
    }

    /// Ranges and relations serde cannot check.
    pub fn check(&self) -> Result<(), Invalid> {
        if !(10..=2000).contains(&self.physics_hz) {
            return Invalid::err("physics_hz", format!("{} Hz", self.physics_hz), "use 10 to 2000 Hz");
        }
        if !(self.realtime_factor > 0.0 && self.realtime_factor <= 100.0) {
            return Invalid::err("realtime_factor", format!("{}", self.realtime_factor), "use a factor in (0, 100]");
        }
        let r = &self.rates_hz;
        for (key, v) in [
            ("rates_hz.speed", r.speed),
            ("rates_hz.state", r.state),
            ("rates_hz.clock", r.clock),
            ("rates_hz.camera", r.camera),
        ] {
            if !(v > 0.0 && v <= self.physics_hz as f64) {
                return Invalid::err(
                    key,
                    format!("{v} Hz"),
                    format!("use a rate in (0, physics_hz = {}]", self.physics_hz),
                );
            }
        }
        self.camera.check("camera")?;
        if !self.camera.enabled {
            return Invalid::err("camera.enabled", "false", "the front camera is always on; remove the key");
        }
        if self.narrow_camera.enabled {
            self.narrow_camera.check("narrow_camera")?;
        }
        if self.mode == Mode::Lockstep && self.lockstep.wait_for.is_empty() {
            return Invalid::err(
                "lockstep.wait_for",
                "lockstep with no node to wait for",
                "name the controller node(s), e.g. [\"acc\"]",
            );
        }
        if self.lockstep.step_timeout_ms == 0 {
            return Invalid::err("lockstep.step_timeout_ms", "0 ms", "give a timeout > 0");
        }
        if !(0.0..=1.0).contains(&self.control.timeout_brake) {
            return Invalid::err("control.timeout_brake", format!("{}", self.control.timeout_brake), "use 0 to 1");
        }
        Ok(())
    }

    /// The camera as camera/front/info describes it.
    pub fn camera_info(&self, encoding: ImageEncoding) -> CameraInfo {
        self.camera.info(self.rates_hz.camera, encoding)
    }

    /// The narrow camera as camera/narrow/info describes it, when it is on.
    pub fn narrow_camera_info(&self, encoding: ImageEncoding) -> Option<CameraInfo> {
        self.narrow_camera.enabled.then(|| self.narrow_camera.info(self.rates_hz.camera, encoding))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_settings_parse_and_bad_values_name_key_and_fix() {
        let s = SimSettings::default();
        assert_eq!((s.physics_hz, s.rates_hz.camera, s.camera.width), (500, 20.0, 640));
        let bad = DEFAULT_SIM_CONFIG.replace("physics_hz: 500", "physics_hz: 5");
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

    #[test]
    fn the_narrow_camera_is_on_by_default_can_be_turned_off_and_is_checked() {
        let on = SimSettings::default().narrow_camera_info(ImageEncoding::Rgb8).unwrap();
        assert_eq!((on.width, on.height), (1152, 320));
        // 3.3 times the front camera's focal length: a vehicle 3.3 times as many pixels wide.
        let front = SimSettings::default().camera_info(ImageEncoding::Rgb8);
        assert!((on.fx_px / front.fx_px - 3.30).abs() < 0.01, "{} / {}", on.fx_px, front.fx_px);
        let off = SimSettings::parse("{ narrow_camera: { enabled: false } }", "mine.json5").unwrap();
        assert!(off.narrow_camera_info(ImageEncoding::Rgb8).is_none());
        let e = SimSettings::parse("{ narrow_camera: { horizontal_fov_deg: 5 } }", "mine.json5").unwrap_err();
        assert_eq!(e.key, "narrow_camera.horizontal_fov_deg");
        let e = SimSettings::parse("{ camera: { enabled: false } }", "mine.json5").unwrap_err();
        assert_eq!(e.key, "camera.enabled");
    }
}
