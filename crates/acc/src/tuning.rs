//! The ACC's tuning: every behavioural number of its parts, by the part that reads it, so that
//! none hides in the code and any can be tried from a settings file (`tuning` in
//! config/acc.json5, which gives each one's unit, meaning and why it has its value).

use serde::Deserialize;

/// The `tuning` settings group.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tuning {
    pub select: SelectTuning,
    pub filter: FilterTuning,
    pub threat: ThreatTuning,
    pub belief: BeliefTuning,
    pub decision: DecisionTuning,
    pub command: CommandTuning,
    pub low_level: LowLevelTuning,
}

/// Lead selection: the tracks' lateral speed, a lead missing from a frame, the lane beyond it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SelectTuning {
    pub lateral_rate_filter: Share,
    pub max_lateral_rate_mps: Amount,
    pub lead_coast_s: Amount,
    pub standing_coast_s: Amount,
    pub standing_lead_mps: Amount,
    pub beyond_lead_m: Amount,
}

/// The lead estimate (the Kalman filter): manoeuvre detection, the lamps, a new lead's
/// settling and the measured noise of its speed.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterTuning {
    pub settle_s: Amount,
    pub new_lead_accel_sigma_mps2: Amount,
    pub manoeuvre_drift_gain: Share,
    pub manoeuvre_drift: Amount,
    pub manoeuvre_accel_sigma_mps2: Amount,
    pub manoeuvre_window_s: Amount,
    pub manoeuvre_hold_s: Amount,
    pub braking_jerk_sigma_mps3: Amount,
    pub slowing_mps2: Amount,
    pub relit_s: Amount,
    pub lit_held_s: Amount,
    pub lamps_vouch_noise_mps: Amount,
    pub speed_noise_gain: Share,
    pub steady_full_gap_m: Amount,
}

/// The threat: the margin it keeps, and when a lead counts as braking to a stop.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThreatTuning {
    pub margin_m: Amount,
    pub braking_mps2: Amount,
}

/// The lead belief: what the lead plausibly does, from its estimate, lamps and age.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeliefTuning {
    pub unmeasured_sigmas: Amount,
    pub unsettled_wait_share: Share,
    pub lit_anticipation_s: Amount,
    pub lit_need_share: Share,
    pub hard_braking_min_speed_mps: Amount,
    pub hard_braking_release_mps2: Amount,
    pub ground_truth_hard_braking_margin_mps2: Amount,
}

/// The decision between comfort braking and an emergency.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecisionTuning {
    pub needed_guard_mps2: Amount,
    pub emergency_factor: Amount,
    pub under_braking_s: Amount,
    pub confirm_s: Amount,
    pub wait_s: Amount,
    pub planned_emergency_mps2: Amount,
    pub release_share: Share,
}

/// The comfort command: the far cap and the release of braking.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandTuning {
    pub far_time_gaps: Amount,
    pub far_closing_mps2: Amount,
    pub far_decel_mps2: Amount,
    pub far_braking_mps2: Amount,
    pub release_jerk_mps3: Amount,
    pub standstill_hold_mps2: Amount,
    pub drive_off_gap_m: Amount,
    pub drive_off_lead_mps: Amount,
}

/// The low-level loop from target acceleration to throttle and brake.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LowLevelTuning {
    pub standstill_mps: Amount,
    pub hold_brake: Share,
    pub integral_gain_per_s: Amount,
    pub integral_max_mps2: Amount,
}

/// A tuning number: finite and at least 0, checked as it is read, so that no key of the
/// tuning can hold anything else (a key is typed `Amount` or `Share`, never a bare f64).
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Deserialize)]
#[serde(try_from = "f64")]
pub struct Amount(f64);

/// A share, a gain per frame or a filter constant: 0 to 1, checked as it is read.
#[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Deserialize)]
#[serde(try_from = "f64")]
pub struct Share(f64);

impl Amount {
    pub const fn get(self) -> f64 {
        self.0
    }
}

impl Share {
    pub const fn get(self) -> f64 {
        self.0
    }
}

impl TryFrom<f64> for Amount {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        match v.is_finite() && v >= 0.0 {
            true => Ok(Amount(v)),
            false => Err(format!("{v} is not a finite value >= 0")),
        }
    }
}

impl TryFrom<f64> for Share {
    type Error = String;
    fn try_from(v: f64) -> Result<Self, String> {
        match (0.0..=1.0).contains(&v) {
            true => Ok(Share(v)),
            false => Err(format!("{v} is not a share from 0 to 1")),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::settings::{AccSettings, DEFAULT_ACC_CONFIG};

    /// Every key of the shipped tuning, set to -1 alone, is refused under its own name; set
    /// to 1.5, refused exactly when it is a share (the file says 0..1 for those).
    #[test]
    fn every_tuning_key_is_range_checked_as_it_is_read() {
        let shipped = slipstream_contract::config::parse_json5_value(DEFAULT_ACC_CONFIG, "shipped").unwrap();
        let tuning = shipped["tuning"].as_object().expect("a tuning section");
        let shares = ["lateral_rate_filter", "manoeuvre_drift_gain", "speed_noise_gain", "unsettled_wait_share"];
        let shares = [&shares[..], &["lit_need_share", "hold_brake", "release_share"]].concat();
        let mut checked = 0;
        for (part, keys) in tuning {
            for key in keys.as_object().expect("a part").keys() {
                let refused = |v: &str| {
                    let text = format!("{{ tuning: {{ {part}: {{ {key}: {v} }} }} }}");
                    AccSettings::parse(&text, "mine.json5").err().map(|e| e.key)
                };
                let name = format!("tuning.{part}.{key}");
                assert_eq!(refused("-1").as_deref(), Some(name.as_str()), "{name} = -1");
                assert_eq!(refused("1.5").is_some(), shares.contains(&key.as_str()), "{name} = 1.5");
                checked += 1;
            }
        }
        assert!(checked >= 48, "{checked} keys");
    }
}
