//! How the ACC drives: config/acc.json5 documents every key and holds the defaults; a settings
//! file of one's own needs only the keys it changes.

use std::path::Path;

use serde::Deserialize;

use super::in_lane::OffsetSigma;
use super::tuning::Tuning;
use slipstream_contract::config::{parse_layered, read_config, ConfigError, Invalid};
use slipstream_model::vehicle::VehicleParams;

pub const DEFAULT_ACC_CONFIG: &str = include_str!("../../../config/acc.json5");
pub(crate) const DEFAULT_ACC_CONFIG_PATH: &str = "config/acc.json5";

const FIX: &str = "see the comments in config/acc.json5 for every key and its allowed values";

/// Where the vehicles ahead come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PerceptionSource {
    /// perception/objects from slipstream-detect.
    Camera,
    /// objects: the simulator's ground truth.
    GroundTruth,
}

impl PerceptionSource {
    /// As written on the command line (`--perception`) and in the config.
    pub fn name(self) -> &'static str {
        match self {
            PerceptionSource::Camera => "camera",
            PerceptionSource::GroundTruth => "ground-truth",
        }
    }
}

/// The longest `perception_wait_ms` the settings take.
pub(crate) const MAX_PERCEPTION_WAIT_MS: u64 = 50;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccSettings {
    pub enabled: bool,
    pub set_speed_mps: f64,
    pub time_gap_s: f64,
    pub standstill_m: f64,
    pub perception: PerceptionSource,
    pub perception_node: String,
    pub lockstep: bool,
    pub lockstep_wait_ms: u64,
    pub perception_wait_ms: u64,
    pub limits: Limits,
    pub gains: Gains,
    pub emergency: Emergency,
    pub stale: Stale,
    pub lane: Lane,
    pub estimator: Estimator,
    pub vehicle: Vehicle,
    pub status_hz: f64,
    pub tuning: Tuning,
    /// Which of the driver's settings the scenario's sim/ego sets when it comes: the ones no
    /// flag gave (`--set-speed`, `--time-gap`), so a slipstream-acc started by hand beside a
    /// simulator drives the scenario's set speed and time gap, as `up` hands them to its nodes.
    #[serde(skip)]
    pub from_scenario: FromScenario,
}

/// The driver's settings the scenario's sim/ego may set ([`AccSettings::from_scenario`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FromScenario {
    pub set_speed: bool,
    pub time_gap: bool,
}

impl Default for FromScenario {
    fn default() -> Self {
        FromScenario { set_speed: true, time_gap: true }
    }
}

impl FromScenario {
    /// The command sim/ego's settings make of `ego`, keeping what a flag gave; None when it
    /// changes nothing.
    pub fn command(self, ego: &slipstream_contract::msg::EgoInfo) -> Option<slipstream_contract::msg::AccCommand> {
        let set_speed_mps = self.set_speed.then_some(ego.set_speed_mps);
        let time_gap_s = if self.time_gap { ego.time_gap_s } else { None };
        (set_speed_mps.is_some() || time_gap_s.is_some()).then_some(slipstream_contract::msg::AccCommand {
            enable: None,
            set_speed_mps,
            time_gap_s,
        })
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    pub accel_mps2: f64,
    /// The comfort deceleration at COMFORT_HIGH_SPEED_MPS and above.
    pub decel_mps2: f64,
    /// The comfort deceleration at COMFORT_LOW_SPEED_MPS and below (linear between).
    pub low_speed_decel_mps2: f64,
    pub jerk_mps3: f64,
}

impl Limits {
    /// The comfort deceleration at speed `v`.
    pub(crate) fn decel_at(&self, v_mps: f64) -> f64 {
        comfort_decel_at(v_mps, self.decel_mps2, self.low_speed_decel_mps2)
    }
}

/// Full-speed-range ACC (ISO 22179, and ISO 15622's FSRA type) lets the comfort deceleration
/// grow as the speed falls: `high` at this speed and above...
pub const COMFORT_HIGH_SPEED_MPS: f64 = 20.0;
/// ...`low` (the larger) at this speed and below, linear between.
pub const COMFORT_LOW_SPEED_MPS: f64 = 5.0;

/// The comfort deceleration at speed `v`: `high` at COMFORT_HIGH_SPEED_MPS and above, `low` at
/// COMFORT_LOW_SPEED_MPS and below, linear between.
pub fn comfort_decel_at(v_mps: f64, high: f64, low: f64) -> f64 {
    let f = ((COMFORT_HIGH_SPEED_MPS - v_mps) / (COMFORT_HIGH_SPEED_MPS - COMFORT_LOW_SPEED_MPS)).clamp(0.0, 1.0);
    high + (low - high) * f
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gains {
    pub gap_per_s2: f64,
    pub speed_per_s: f64,
    pub cruise_per_s: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Emergency {
    pub warn_ttc_s: f64,
    pub brake_ttc_s: f64,
    pub full_brake_ttc_s: f64,
    pub release_ttc_s: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stale {
    pub speed_max_age_ms: u64,
    pub perception_max_age_ms: u64,
    pub decel_mps2: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lane {
    pub in_lane_m: f64,
    pub stay_in_lane_m: f64,
    pub in_lane_probability: f64,
    pub offset_sigma: OffsetSigma,
    pub lateral_lookahead_s: f64,
    pub range_m: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Estimator {
    pub gap_sigma_m: f64,
    pub gap_sigma_per_m2: f64,
    pub speed_sigma_mps: f64,
    /// The relative speed's noise grows with range like the range's: speed_sigma_mps +
    /// speed_sigma_per_m2 * gap^2 (0 when left out).
    #[serde(default)]
    pub speed_sigma_per_m2: f64,
    /// Outside a manoeuvre the relative speed is smoothed as if this noisy (a lead holding its
    /// speed is followed calmly) from 50 m on, nearer less; default: no extra smoothing.
    #[serde(default)]
    pub steady_speed_sigma_mps: f64,
    pub lead_jerk_sigma_mps3: f64,
    /// How far the lead's estimated deceleration may overshoot its true one (m/s2): a lead
    /// counts as braking beyond the comfort limit (answered at once, in an emergency) when
    /// its estimate is beyond the limit by more than this. Default 0.7: the camera's estimate
    /// overshoots by up to 0.5 for leads braking at 2.5-3.5 m/s2; ground truth uses 0.1.
    #[serde(default = "default_hard_braking_margin")]
    pub hard_braking_margin_mps2: f64,
}

fn default_hard_braking_margin() -> f64 {
    0.7
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vehicle {
    pub mass_kg: f64,
    pub max_drive_force_n: f64,
    pub max_power_w: f64,
    pub max_brake_decel_mps2: f64,
    pub drag_area_m2: f64,
    pub rolling_coeff: f64,
    /// First-order lag of throttle and brake, seconds: compensated by asking for the target
    /// plus lag x its rate of change.
    pub actuator_lag_s: f64,
    pub front_overhang_from_origin_m: f64,
}

impl Vehicle {
    /// The model of a vehicle type: what the ACC drives (`slipstream-acc --vehicle`).
    pub fn of(p: &VehicleParams) -> Vehicle {
        Vehicle {
            mass_kg: p.mass_kg,
            max_drive_force_n: p.max_drive_force_n,
            max_power_w: p.max_power_w,
            max_brake_decel_mps2: p.max_brake_decel_mps2,
            drag_area_m2: p.drag_area_m2,
            rolling_coeff: p.rolling_coeff,
            actuator_lag_s: p.actuator_lag_s,
            front_overhang_from_origin_m: p.size_m[0] - p.rear_overhang_m,
        }
    }

    /// The model as the simulator's vehicle type (only the longitudinal numbers matter).
    pub fn params(&self) -> VehicleParams {
        VehicleParams {
            mass_kg: self.mass_kg,
            max_drive_force_n: self.max_drive_force_n,
            max_power_w: self.max_power_w,
            max_brake_decel_mps2: self.max_brake_decel_mps2,
            drag_area_m2: self.drag_area_m2,
            rolling_coeff: self.rolling_coeff,
            actuator_lag_s: self.actuator_lag_s,
            ..VehicleParams::CAR
        }
    }
}

impl Default for AccSettings {
    fn default() -> Self {
        AccSettings::parse(DEFAULT_ACC_CONFIG, DEFAULT_ACC_CONFIG_PATH).expect("config/acc.json5 is valid")
    }
}

/// The set speeds the ACC accepts, m/s (252 km/h: above any road's limit, below the number
/// a sign error or a km/h value typed as m/s would give).
pub(crate) const SET_SPEED_RANGE_MPS: std::ops::RangeInclusive<f64> = 0.0..=70.0;

/// The time gaps the ACC accepts (ISO 15622 asks at least 0.8 s).
pub(crate) const TIME_GAP_RANGE_S: std::ops::RangeInclusive<f64> = 0.8..=3.0;

impl AccSettings {
    /// Settings from a file, or the built-in defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<AccSettings, ConfigError> {
        let Some(path) = path else { return Ok(AccSettings::default()) };
        let (text, origin) = read_config(path)?;
        AccSettings::parse(&text, &origin)
    }

    /// Parses settings text laid over the defaults.
    pub fn parse(text: &str, origin: &str) -> Result<AccSettings, ConfigError> {
        let s: AccSettings = parse_layered(DEFAULT_ACC_CONFIG, DEFAULT_ACC_CONFIG_PATH, text, origin, FIX)?;
        s.check().map_err(|i| i.at(origin))?;
        Ok(s)
    }

    /// Ranges and relations serde cannot check: the first one off. (The tuning's ranges are
    /// its values' types, checked as they are read.)
    pub fn check(&self) -> Result<(), Invalid> {
        self.check_law()?;
        self.check_inputs_and_vehicle()
    }

    /// The control law: speeds, gaps, comfort limits, gains, emergency and stale thresholds.
    fn check_law(&self) -> Result<(), Invalid> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !SET_SPEED_RANGE_MPS.contains(&self.set_speed_mps) {
            return Invalid::err("set_speed_mps", format!("{}", self.set_speed_mps), "use 0 to 70 m/s");
        }
        if !TIME_GAP_RANGE_S.contains(&self.time_gap_s) {
            return Invalid::err("time_gap_s", format!("{} s", self.time_gap_s), "use 0.8 to 3.0 s");
        }
        if !(self.standstill_m.is_finite() && (1.0..=20.0).contains(&self.standstill_m)) {
            return Invalid::err("standstill_m", format!("{} m", self.standstill_m), "use 1 to 20 m");
        }
        let l = &self.limits;
        for (key, v) in [
            ("limits.accel_mps2", l.accel_mps2),
            ("limits.decel_mps2", l.decel_mps2),
            ("limits.low_speed_decel_mps2", l.low_speed_decel_mps2),
            ("limits.jerk_mps3", l.jerk_mps3),
        ] {
            if !positive(v) {
                return Invalid::err(key, format!("{v}"), "give a limit > 0");
            }
        }
        if l.decel_mps2 >= self.vehicle.max_brake_decel_mps2 {
            return Invalid::err(
                "limits.decel_mps2",
                format!("{} is not below the vehicle's {} m/s2", l.decel_mps2, self.vehicle.max_brake_decel_mps2),
                "keep the comfort limit below vehicle.max_brake_decel_mps2 (emergencies use the rest)",
            );
        }
        if !(l.decel_mps2..self.vehicle.max_brake_decel_mps2).contains(&l.low_speed_decel_mps2) {
            return Invalid::err(
                "limits.low_speed_decel_mps2",
                format!(
                    "{} is not between limits.decel_mps2 ({}) and the vehicle's {} m/s2",
                    l.low_speed_decel_mps2, l.decel_mps2, self.vehicle.max_brake_decel_mps2
                ),
                "use a value from limits.decel_mps2 up to below vehicle.max_brake_decel_mps2 (ISO 22179: 5)",
            );
        }
        let g = &self.gains;
        for (key, v) in [
            ("gains.gap_per_s2", g.gap_per_s2),
            ("gains.speed_per_s", g.speed_per_s),
            ("gains.cruise_per_s", g.cruise_per_s),
        ] {
            if !positive(v) {
                return Invalid::err(key, format!("{v}"), "give a gain > 0");
            }
        }
        let e = &self.emergency;
        if !(positive(e.full_brake_ttc_s)
            && e.full_brake_ttc_s <= e.brake_ttc_s
            && e.brake_ttc_s <= e.warn_ttc_s
            && e.brake_ttc_s < e.release_ttc_s)
        {
            return Invalid::err(
                "emergency",
                format!(
                    "full_brake {} / brake {} / warn {} / release {} s",
                    e.full_brake_ttc_s, e.brake_ttc_s, e.warn_ttc_s, e.release_ttc_s
                ),
                "order them 0 < full_brake_ttc_s <= brake_ttc_s <= warn_ttc_s and brake_ttc_s < release_ttc_s",
            );
        }
        if self.stale.speed_max_age_ms == 0 || self.stale.perception_max_age_ms == 0 {
            return Invalid::err("stale", "an age of 0 ms", "give ages > 0");
        }
        if !(positive(self.stale.decel_mps2) && self.stale.decel_mps2 <= l.decel_mps2) {
            return Invalid::err(
                "stale.decel_mps2",
                format!("{}", self.stale.decel_mps2),
                "use a value in (0, limits.decel_mps2]",
            );
        }
        Ok(())
    }

    /// Lead selection, the lead estimator, the vehicle model, the status rate, the detector.
    fn check_inputs_and_vehicle(&self) -> Result<(), Invalid> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let n = &self.lane;
        if !(positive(n.in_lane_m)
            && n.stay_in_lane_m >= n.in_lane_m
            && positive(n.range_m)
            && n.lateral_lookahead_s >= 0.0)
        {
            return Invalid::err(
                "lane",
                format!("{n:?}"),
                "in_lane_m > 0, stay_in_lane_m >= in_lane_m, range_m > 0, lookahead >= 0",
            );
        }
        if !(n.in_lane_probability > 0.0 && n.in_lane_probability < 1.0) {
            return Invalid::err(
                "lane.in_lane_probability",
                format!("{}", n.in_lane_probability),
                "give a value between 0 and 1",
            );
        }
        n.offset_sigma.check("lane.offset_sigma")?;
        let e = &self.estimator;
        for (key, x) in [
            ("estimator.gap_sigma_m", e.gap_sigma_m),
            ("estimator.speed_sigma_mps", e.speed_sigma_mps),
            ("estimator.lead_jerk_sigma_mps3", e.lead_jerk_sigma_mps3),
        ] {
            if !positive(x) {
                return Invalid::err(key, format!("{x}"), "give a value > 0");
            }
        }
        for (key, x) in [
            ("estimator.gap_sigma_per_m2", e.gap_sigma_per_m2),
            ("estimator.speed_sigma_per_m2", e.speed_sigma_per_m2),
            ("estimator.steady_speed_sigma_mps", e.steady_speed_sigma_mps),
            ("estimator.hard_braking_margin_mps2", e.hard_braking_margin_mps2),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Invalid::err(key, format!("{x}"), "give a value >= 0");
            }
        }
        let v = &self.vehicle;
        for (key, x) in [
            ("vehicle.mass_kg", v.mass_kg),
            ("vehicle.max_drive_force_n", v.max_drive_force_n),
            ("vehicle.max_power_w", v.max_power_w),
            ("vehicle.max_brake_decel_mps2", v.max_brake_decel_mps2),
        ] {
            if !positive(x) {
                return Invalid::err(key, format!("{x}"), "give a value > 0");
            }
        }
        if !(positive(self.status_hz) && self.status_hz <= 100.0) {
            return Invalid::err("status_hz", format!("{}", self.status_hz), "use (0, 100] Hz");
        }
        if self.perception_node.is_empty() {
            return Invalid::err("perception_node", "empty", "name the detector node, e.g. \"detect\"");
        }
        if self.perception_wait_ms > MAX_PERCEPTION_WAIT_MS {
            return Invalid::err(
                "perception_wait_ms",
                format!("{} ms", self.perception_wait_ms),
                format!("use 0 to {MAX_PERCEPTION_WAIT_MS} ms: an answer held longer than the speed messages' period (10 ms at 100 Hz) makes the next ones queue"),
            );
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_is_the_default_and_a_file_needs_only_its_changes() {
        let d = AccSettings::default();
        assert_eq!(d.time_gap_s, 1.8);
        let s = AccSettings::parse("{ time_gap_s: 2.2, perception: 'ground-truth' }", "mine.json5").unwrap();
        assert_eq!(s.time_gap_s, 2.2);
        assert_eq!(s.perception, PerceptionSource::GroundTruth);
        assert_eq!(s.limits, d.limits);
    }

    /// The shipped vehicle section is the simulator's car; `--vehicle` puts another type's
    /// numbers in its place.
    #[test]
    fn the_shipped_vehicle_is_the_simulators_car_and_a_class_gives_its_own() {
        use crate::VehicleClass;
        let (shipped, car) = (AccSettings::default().vehicle, Vehicle::of(&VehicleParams::CAR));
        assert!((shipped.front_overhang_from_origin_m - car.front_overhang_from_origin_m).abs() < 1e-9);
        assert_eq!(shipped, Vehicle { front_overhang_from_origin_m: shipped.front_overhang_from_origin_m, ..car });
        let args = |extra: &[&str]| {
            let mut argv = vec!["acc"];
            argv.extend_from_slice(extra);
            #[derive(clap::Parser)]
            struct Cli {
                #[command(flatten)]
                acc: crate::args::AccArgs,
            }
            <Cli as clap::Parser>::parse_from(argv).acc.settings().unwrap()
        };
        let truck = args(&["--vehicle", "truck"]).vehicle;
        assert_eq!((truck.mass_kg, truck.max_brake_decel_mps2, truck.actuator_lag_s), (12_000.0, 6.5, 0.5));
        assert!((truck.front_overhang_from_origin_m - 7.3).abs() < 1e-9);
        let motorcycle = Vehicle::of(&VehicleClass::Motorcycle.params());
        assert!((motorcycle.front_overhang_from_origin_m - 1.85).abs() < 1e-9);
        assert_eq!(args(&[]).vehicle, AccSettings::default().vehicle);
    }

    #[test]
    fn bad_values_name_the_file_key_and_fix() {
        let e = AccSettings::parse("{ time_gap_s: 0.5 }", "mine.json5").unwrap_err();
        assert_eq!((e.origin.as_str(), e.key.as_str()), ("mine.json5", "time_gap_s"));
        assert!(e.fix.contains("0.8"), "{e}");
        let e = AccSettings::parse("{ limits: { decel_mps2: 9.5 } }", "f").unwrap_err();
        assert_eq!(e.key, "limits.decel_mps2");
        let e = AccSettings::parse("{ perception: 'lidar' }", "f").unwrap_err();
        assert_eq!(e.key, "perception");
        let e = AccSettings::parse("{ gains: { gap: 1 } }", "f").unwrap_err();
        assert!(e.key.starts_with("gains"), "{e}");
    }
}
