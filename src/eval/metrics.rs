//! Judging the ACC: the figures of one run (from the simulator's ground truth, not from the
//! ACC's own view) and pass/fail against the aims.

use serde::Serialize;

use super::fmt_opt;
use super::trace::{Sample, Trace};
use crate::msg::AccMode;

/// The aims of issue 5 (docs/control.md).
pub mod aims {
    pub const TIME_GAP_RMS_S: f64 = 0.1;
    pub const MAX_ACCEL_MPS2: f64 = 2.0;
    pub const MAX_DECEL_MPS2: f64 = 3.5;
    pub const MAX_JERK_MPS3: f64 = 2.5;
    /// Tolerance on the measured acceleration and deceleration: the vehicle's response to a
    /// limited target overshoots a little (tyre and suspension dynamics of the physics
    /// engine). Jerk has none (issue 16): the controller limits it to 2.2 m/s3.
    pub const COMFORT_TOLERANCE: f64 = 0.1;
}

/// How long a stretch must last before it counts as steady.
const STEADY_S: f64 = 10.0;
/// Samples this close (before, after) to an emergency belong to it.
const EMERGENCY_MARGIN_S: (f64, f64) = (0.1, 1.5);
/// Jerk is taken over this window of measured acceleration.
const JERK_WINDOW_S: f64 = 0.1;
/// Below this speed comfort is not judged: a car stopping on its brakes has a jerk spike at the
/// instant it stops, and ISO 15622 puts its jerk limit on driving at speed.
const COMFORT_MIN_SPEED_MPS: f64 = 2.0;
/// The first moments of a run belong to the simulator: until the controller's first command
/// arrives the ego cruises (realtime runs), so the step to the controller's acceleration is
/// the handover, not the controller's comfort. Jerk is judged from here on.
const HANDOVER_S: f64 = 0.2;

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub name: String,
    pub value: Option<f64>,
    pub aim: String,
    pub pass: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    pub duration_s: f64,
    pub collisions: u64,
    pub min_gap_m: Option<f64>,
    pub min_ttc_s: Option<f64>,
    pub time_gap_rms_error_s: Option<f64>,
    /// Simulated seconds of steady following the time-gap error was taken over.
    pub steady_follow_s: f64,
    pub speed_rmse_mps: Option<f64>,
    pub steady_speed_s: f64,
    pub max_accel_mps2: f64,
    /// Outside emergencies and at speed.
    pub max_decel_mps2: f64,
    pub max_jerk_mps3: f64,
    pub emergency_s: f64,
    pub max_decel_in_emergency_mps2: f64,
    pub checks: Vec<Check>,
    pub pass: bool,
}

fn rms(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
}

/// What one pass over a trace gathers.
#[derive(Default)]
struct Tally {
    min_gap: Option<f64>,
    min_ttc: Option<f64>,
    /// Time-gap errors in steady following, speed errors in steady speed mode.
    gap_errors: Vec<f64>,
    speed_errors: Vec<f64>,
    max_accel: f64,
    max_decel: f64,
    max_jerk: f64,
    max_em_decel: f64,
    /// Start of the current stretch with the same truth lead, and of the current stretch in
    /// speed mode at the same set speed: (lead id or set speed, sample index).
    lead_since: Option<(u32, usize)>,
    speed_since: Option<(f64, usize)>,
}

/// Steady following: the same lead for 2 x STEADY_S (time to settle), its speed within 1 m/s
/// over the last STEADY_S of `stretch`, which ends at `now`.
fn steady_lead(stretch: &[Sample], now: &Sample) -> bool {
    if now.t_s - stretch[0].t_s < 2.0 * STEADY_S {
        return false;
    }
    let lead_speed = |w: &Sample| w.speed_mps + w.truth.map_or(0.0, |t| t.relative_speed_mps);
    let (lo, hi) = stretch
        .iter()
        .filter(|w| w.t_s >= now.t_s - STEADY_S)
        .map(lead_speed)
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    hi - lo < 1.0
}

impl Tally {
    /// The true lead at sample `i`: smallest gap and TTC; the time-gap error once following
    /// has been steady.
    fn lead(&mut self, s: &[Sample], i: usize, standstill_m: f64) {
        let x = &s[i];
        let Some(tl) = x.truth else {
            self.lead_since = None;
            return;
        };
        self.min_gap = Some(self.min_gap.map_or(tl.gap_m, |m| m.min(tl.gap_m)));
        if -tl.relative_speed_mps > 0.1 {
            let ttc = tl.gap_m.max(0.0) / -tl.relative_speed_mps;
            self.min_ttc = Some(self.min_ttc.map_or(ttc, |m| m.min(ttc)));
        }
        if self.lead_since.is_none_or(|(id, _)| id != tl.id) {
            self.lead_since = Some((tl.id, i));
        }
        let from = self.lead_since.map_or(i, |(_, from)| from);
        if x.mode == AccMode::Follow && x.speed_mps > 3.0 && steady_lead(&s[from..=i], x) {
            self.gap_errors.push((tl.gap_m - standstill_m) / x.speed_mps - x.time_gap_s);
        }
    }

    /// Speed mode at sample `i`: the speed error once at the same set speed for STEADY_S.
    fn speed_mode(&mut self, s: &[Sample], i: usize) {
        let x = &s[i];
        if x.mode != AccMode::Speed {
            self.speed_since = None;
            return;
        }
        if self.speed_since.is_none_or(|(v, _)| v != x.set_speed_mps) {
            self.speed_since = Some((x.set_speed_mps, i));
        }
        if self.speed_since.is_some_and(|(_, from)| x.t_s - s[from].t_s >= STEADY_S) {
            self.speed_errors.push(x.speed_mps - x.set_speed_mps);
        }
    }

    /// Acceleration, deceleration and jerk (over `jerk_lag` samples) at sample `i`, at speed
    /// and away from emergencies; the deceleration in emergencies.
    fn comfort(&mut self, s: &[Sample], i: usize, jerk_lag: usize, near_emergency: bool) {
        let x = &s[i];
        if x.mode == AccMode::Emergency {
            self.max_em_decel = self.max_em_decel.max(-x.accel_mps2);
        }
        if near_emergency || x.speed_mps < COMFORT_MIN_SPEED_MPS {
            return;
        }
        self.max_accel = self.max_accel.max(x.accel_mps2);
        self.max_decel = self.max_decel.max(-x.accel_mps2);
        if i >= jerk_lag
            && s[i - jerk_lag].speed_mps >= COMFORT_MIN_SPEED_MPS
            && s[i - jerk_lag].t_s - s[0].t_s >= HANDOVER_S
        {
            let p = &s[i - jerk_lag];
            let j = (x.accel_mps2 - p.accel_mps2) / (x.t_s - p.t_s).max(1e-6);
            self.max_jerk = self.max_jerk.max(j.abs());
        }
    }

    /// Pass or fail against the aims.
    fn checks(&self, collisions: u64, time_gap_rms: Option<f64>) -> Vec<Check> {
        let tol = 1.0 + aims::COMFORT_TOLERANCE;
        let comfort = |name: &str, value: f64, aim: f64| Check {
            name: name.into(),
            value: Some(value),
            aim: format!("<= {aim} (+{:.0}%)", aims::COMFORT_TOLERANCE * 100.0),
            pass: value <= aim * tol,
        };
        let mut checks = vec![
            Check { name: "collisions".into(), value: Some(collisions as f64), aim: "0".into(), pass: collisions == 0 },
            Check {
                name: "min gap (m)".into(),
                value: self.min_gap,
                aim: "> 0".into(),
                pass: self.min_gap.is_none_or(|g| g > 0.0),
            },
        ];
        if let Some(e) = time_gap_rms {
            checks.push(Check {
                name: "time-gap RMS error, steady following (s)".into(),
                value: Some(e),
                aim: format!("<= {}", aims::TIME_GAP_RMS_S),
                pass: e <= aims::TIME_GAP_RMS_S,
            });
        }
        checks.push(comfort("max accel outside emergencies (m/s2)", self.max_accel, aims::MAX_ACCEL_MPS2));
        checks.push(comfort("max decel outside emergencies (m/s2)", self.max_decel, aims::MAX_DECEL_MPS2));
        // Jerk is judged strictly: the controller's own limit sits below the aim, with room for
        // the vehicle's response.
        checks.push(Check {
            name: "max jerk outside emergencies (m/s3)".into(),
            value: Some(self.max_jerk),
            aim: format!("<= {}", aims::MAX_JERK_MPS3),
            pass: self.max_jerk <= aims::MAX_JERK_MPS3,
        });
        checks
    }
}

impl Metrics {
    /// The headline figures as text, each with its own precision, in this order: min gap (m),
    /// min TTC (s), time-gap RMS error (s), speed RMSE (m/s), max accel, max decel (m/s2), max
    /// jerk (m/s3). "-" where a figure does not apply. The same in every report.
    pub fn headline(&self) -> [String; 7] {
        [
            fmt_opt(self.min_gap_m, 1),
            fmt_opt(self.min_ttc_s, 2),
            fmt_opt(self.time_gap_rms_error_s, 3),
            fmt_opt(self.speed_rmse_mps, 3),
            format!("{:.2}", self.max_accel_mps2),
            format!("{:.2}", self.max_decel_mps2),
            format!("{:.2}", self.max_jerk_mps3),
        ]
    }

    pub fn of(trace: &Trace) -> Metrics {
        let s = &trace.samples;
        let dt = if s.len() > 1 { (s[s.len() - 1].t_s - s[0].t_s) / (s.len() - 1) as f64 } else { 0.01 };
        let emergency_times: Vec<f64> = s.iter().filter(|x| x.mode == AccMode::Emergency).map(|x| x.t_s).collect();
        // From a little before an emergency to a while after it (the release).
        let near_emergency =
            |t: f64| emergency_times.iter().any(|&e| e >= t - EMERGENCY_MARGIN_S.1 && e <= t + EMERGENCY_MARGIN_S.0);
        let jerk_lag = (JERK_WINDOW_S / dt.max(1e-6)).round().max(1.0) as usize;
        let mut tally = Tally::default();
        for i in 0..s.len() {
            tally.lead(s, i, trace.standstill_m);
            tally.speed_mode(s, i);
            tally.comfort(s, i, jerk_lag, near_emergency(s[i].t_s));
        }
        let time_gap_rms = rms(&tally.gap_errors);
        let checks = tally.checks(trace.collisions, time_gap_rms);
        Metrics {
            duration_s: s.last().map_or(0.0, |x| x.t_s),
            collisions: trace.collisions,
            min_gap_m: tally.min_gap,
            min_ttc_s: tally.min_ttc,
            time_gap_rms_error_s: time_gap_rms,
            steady_follow_s: tally.gap_errors.len() as f64 * dt,
            speed_rmse_mps: rms(&tally.speed_errors),
            steady_speed_s: tally.speed_errors.len() as f64 * dt,
            max_accel_mps2: tally.max_accel,
            max_decel_mps2: tally.max_decel,
            max_jerk_mps3: tally.max_jerk,
            emergency_s: emergency_times.len() as f64 * dt,
            max_decel_in_emergency_mps2: tally.max_em_decel,
            pass: checks.iter().all(|c| c.pass),
            checks,
        }
    }
}
