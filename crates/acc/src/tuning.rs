//! The ACC's tuning: every behavioural number of its parts, by the part that reads it, so that
//! none hides in the code and any can be tried from a settings file (`tuning` in
//! config/acc.json5, which gives each one's unit, meaning and why it has its value).

use serde::Deserialize;
use slipstream_contract::config::Invalid;

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
    pub lateral_rate_filter: f64,
    pub max_lateral_rate_mps: f64,
    pub lead_coast_s: f64,
    pub standing_coast_s: f64,
    pub standing_lead_mps: f64,
    pub beyond_lead_m: f64,
}

/// The lead estimate (the Kalman filter): manoeuvre detection, the lamps, a new lead's
/// settling and the measured noise of its speed.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterTuning {
    pub settle_s: f64,
    pub new_lead_accel_sigma_mps2: f64,
    pub manoeuvre_drift_gain: f64,
    pub manoeuvre_drift: f64,
    pub manoeuvre_accel_sigma_mps2: f64,
    pub manoeuvre_window_s: f64,
    pub manoeuvre_hold_s: f64,
    pub braking_jerk_sigma_mps3: f64,
    pub slowing_mps2: f64,
    pub relit_s: f64,
    pub lit_held_s: f64,
    pub lamps_vouch_noise_mps: f64,
    pub speed_noise_gain: f64,
    pub steady_full_gap_m: f64,
}

/// The threat: the margin it keeps, and when a lead counts as braking to a stop.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThreatTuning {
    pub margin_m: f64,
    pub braking_mps2: f64,
}

/// The lead belief: what the lead plausibly does, from its estimate, lamps and age.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeliefTuning {
    pub unmeasured_sigmas: f64,
    pub unsettled_wait_share: f64,
    pub lit_anticipation_s: f64,
    pub lit_need_share: f64,
    pub hard_braking_min_speed_mps: f64,
    pub hard_braking_release_mps2: f64,
    pub ground_truth_hard_braking_margin_mps2: f64,
}

/// The decision between comfort braking and an emergency.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DecisionTuning {
    pub needed_guard_mps2: f64,
    pub emergency_factor: f64,
    pub under_braking_s: f64,
    pub confirm_s: f64,
    pub wait_s: f64,
    pub planned_emergency_mps2: f64,
}

/// The comfort command: the far cap and the release of braking.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandTuning {
    pub far_time_gaps: f64,
    pub far_closing_mps2: f64,
    pub far_decel_mps2: f64,
    pub far_braking_mps2: f64,
    pub release_jerk_mps3: f64,
}

/// The low-level loop from target acceleration to throttle and brake.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LowLevelTuning {
    pub standstill_mps: f64,
    pub hold_brake: f64,
    pub integral_gain_per_s: f64,
    pub integral_max_mps2: f64,
}

impl Tuning {
    /// Every number by its key, for the settings' check.
    pub fn entries(&self) -> Vec<(&'static str, f64)> {
        let (s, f, b, d, c, l) =
            (&self.select, &self.filter, &self.belief, &self.decision, &self.command, &self.low_level);
        let t = &self.threat;
        vec![
            ("tuning.select.lateral_rate_filter", s.lateral_rate_filter),
            ("tuning.select.max_lateral_rate_mps", s.max_lateral_rate_mps),
            ("tuning.select.lead_coast_s", s.lead_coast_s),
            ("tuning.select.standing_coast_s", s.standing_coast_s),
            ("tuning.select.standing_lead_mps", s.standing_lead_mps),
            ("tuning.select.beyond_lead_m", s.beyond_lead_m),
            ("tuning.filter.settle_s", f.settle_s),
            ("tuning.filter.new_lead_accel_sigma_mps2", f.new_lead_accel_sigma_mps2),
            ("tuning.filter.manoeuvre_drift_gain", f.manoeuvre_drift_gain),
            ("tuning.filter.manoeuvre_drift", f.manoeuvre_drift),
            ("tuning.filter.manoeuvre_accel_sigma_mps2", f.manoeuvre_accel_sigma_mps2),
            ("tuning.filter.manoeuvre_window_s", f.manoeuvre_window_s),
            ("tuning.filter.manoeuvre_hold_s", f.manoeuvre_hold_s),
            ("tuning.filter.braking_jerk_sigma_mps3", f.braking_jerk_sigma_mps3),
            ("tuning.filter.slowing_mps2", f.slowing_mps2),
            ("tuning.filter.relit_s", f.relit_s),
            ("tuning.filter.lit_held_s", f.lit_held_s),
            ("tuning.filter.lamps_vouch_noise_mps", f.lamps_vouch_noise_mps),
            ("tuning.filter.speed_noise_gain", f.speed_noise_gain),
            ("tuning.filter.steady_full_gap_m", f.steady_full_gap_m),
            ("tuning.threat.margin_m", t.margin_m),
            ("tuning.threat.braking_mps2", t.braking_mps2),
            ("tuning.belief.unmeasured_sigmas", b.unmeasured_sigmas),
            ("tuning.belief.unsettled_wait_share", b.unsettled_wait_share),
            ("tuning.belief.lit_anticipation_s", b.lit_anticipation_s),
            ("tuning.belief.lit_need_share", b.lit_need_share),
            ("tuning.belief.hard_braking_min_speed_mps", b.hard_braking_min_speed_mps),
            ("tuning.belief.hard_braking_release_mps2", b.hard_braking_release_mps2),
            ("tuning.belief.ground_truth_hard_braking_margin_mps2", b.ground_truth_hard_braking_margin_mps2),
            ("tuning.decision.needed_guard_mps2", d.needed_guard_mps2),
            ("tuning.decision.emergency_factor", d.emergency_factor),
            ("tuning.decision.under_braking_s", d.under_braking_s),
            ("tuning.decision.confirm_s", d.confirm_s),
            ("tuning.decision.wait_s", d.wait_s),
            ("tuning.decision.planned_emergency_mps2", d.planned_emergency_mps2),
            ("tuning.command.far_time_gaps", c.far_time_gaps),
            ("tuning.command.far_closing_mps2", c.far_closing_mps2),
            ("tuning.command.far_decel_mps2", c.far_decel_mps2),
            ("tuning.command.far_braking_mps2", c.far_braking_mps2),
            ("tuning.command.release_jerk_mps3", c.release_jerk_mps3),
            ("tuning.low_level.standstill_mps", l.standstill_mps),
            ("tuning.low_level.hold_brake", l.hold_brake),
            ("tuning.low_level.integral_gain_per_s", l.integral_gain_per_s),
            ("tuning.low_level.integral_max_mps2", l.integral_max_mps2),
        ]
    }

    /// The first number that is not a finite, non-negative value, or a share or a filter
    /// constant above 1.
    pub fn check(&self) -> Result<(), Invalid> {
        for (key, v) in self.entries() {
            if !(v.is_finite() && v >= 0.0) {
                return Invalid::err(key, format!("{v}"), "give a finite value >= 0");
            }
            let unit_interval = key.ends_with("_share")
                || key.ends_with("_filter")
                || key.ends_with("_gain")
                || key.ends_with("hold_brake");
            if unit_interval && v > 1.0 {
                return Invalid::err(key, format!("{v}"), "give a value from 0 to 1");
            }
        }
        Ok(())
    }
}
