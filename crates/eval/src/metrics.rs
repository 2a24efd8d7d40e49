//! Judging the ACC: the figures of one run (from the simulator's ground truth, not from the
//! ACC's own view) and pass/fail against the aims.

use serde::Serialize;

use super::fmt_opt;
use super::trace::{Sample, Trace, TruthLead};
use slipstream_acc::settings::{comfort_decel_at, COMFORT_HIGH_SPEED_MPS, COMFORT_LOW_SPEED_MPS};
use slipstream_contract::msg::AccMode;
use slipstream_sim::scenario::Warranted;

/// The ACC's aims (docs/control.md).
pub(crate) mod aims {
    pub(crate) const TIME_GAP_RMS_S: f64 = 0.05;
    /// Settled behind a lead that holds its speed, the ego's acceleration stays this close to
    /// the lead's.
    pub(crate) const MAX_ACCEL_SWING_MPS2: f64 = 0.3;
    pub(crate) const MAX_ACCEL_MPS2: f64 = 2.0;
    /// Comfort deceleration at 20 m/s and above; it grows linearly to MAX_DECEL_LOW_SPEED_MPS2
    /// at 5 m/s and below (full-speed-range ACC, ISO 22179).
    pub(crate) const MAX_DECEL_MPS2: f64 = 3.5;
    pub(crate) const MAX_DECEL_LOW_SPEED_MPS2: f64 = 5.0;
    pub(crate) const MAX_JERK_MPS3: f64 = 2.5;
    /// Easing off braking (the deceleration shrinking) is judged apart: braking for a target
    /// that has gone is to be released at once, and a released brake is felt far less than an
    /// applied one. The ACC's own release jerk (tuning.command.release_jerk_mps3) is 10.
    pub(crate) const MAX_RELEASE_JERK_MPS3: f64 = 12.0;
    /// A lead braking beyond the comfort limit is answered within this long. Reported
    /// in every run, not judged: where comfort braking keeps clear of such a lead, the ACC
    /// answers with the comfort ramp, which takes longer (docs/control.md, results).
    pub(crate) const HARD_BRAKING_RESPONSE_S: f64 = 0.5;
    /// Tolerance on the measured acceleration and deceleration: the vehicle's response to a
    /// limited target overshoots a little (tyre and suspension dynamics of the physics
    /// engine). Jerk has none: the controller limits it to 2.2 m/s3.
    pub(crate) const COMFORT_TOLERANCE: f64 = 0.1;
}

/// How long a stretch must last before it counts as steady.
const STEADY_S: f64 = 10.0;
/// Following: the ego within this of the lead's speed, the lead's speed within this over
/// STEADY_S.
const FOLLOWING_BAND_MPS: f64 = 1.0;
/// Samples this close (before, after) to an emergency belong to it.
const EMERGENCY_MARGIN_S: (f64, f64) = (0.1, 1.5);
/// Braking harder than this with nothing in the lane within twice the time gap (nor closing
/// fast on something farther) is phantom braking, unless a vehicle was there
/// within PHANTOM_GRACE_S before.
const PHANTOM_DECEL_MPS2: f64 = 1.0;
const PHANTOM_GRACE_S: f64 = 1.0;
/// Phantom braking this far apart is one event: a driver feels one false brake, not each
/// dip of it.
const PHANTOM_EVENT_GAP_S: f64 = 2.0;
/// A vehicle farther than that still warrants braking when matching its speed short of it
/// needs this much.
const WARRANTED_BRAKING_MPS2: f64 = 0.5;
/// An emergency is warranted by a vehicle in the lane closing with a TTC below this, or
/// nearer than half the time gap, or braking beyond the comfort limit when stopping behind it
/// needs more than PHANTOM_DECEL_MPS2, from EMERGENCY_LOOKBACK_S before it starts to its end.
const WARRANTED_TTC_S: f64 = 5.0;
const EMERGENCY_LOOKBACK_S: f64 = 0.5;
/// Standing still with nothing in the lane within the standstill distance plus this, for
/// longer than STANDSTILL_GRACE_S, is stopping for nothing.
const STANDSTILL_CLEAR_M: f64 = 15.0;
const STANDSTILL_GRACE_S: f64 = 3.0;
/// Settled: the lead has held its speed within this band for this long.
const SETTLED_S: f64 = 10.0;
const SETTLED_SPEED_BAND_MPS: f64 = 0.3;
const SETTLED_AHEAD_S: f64 = 1.0;
/// The lead's acceleration is taken over this window of its speed.
const LEAD_ACCEL_WINDOW_S: f64 = 0.5;
/// A lead braking harder than this (the comfort limit) is braking hard: the ACC must ask for
/// the deceleration stopping behind it needs (NEED_SHARE of it, counted from the truth) within
/// HARD_BRAKING_RESPONSE_S. The lead's acceleration is taken over
/// HARD_BRAKING_WINDOW_S; stopping behind it keeps HARD_BRAKING_MARGIN_M; an episode ends when
/// it brakes less than PHANTOM_DECEL_MPS2, and counts only if it needed more than that.
const HARD_BRAKING_WINDOW_S: f64 = 0.1;
const HARD_BRAKING_MARGIN_M: f64 = 2.0;
const NEED_SHARE: f64 = 0.9;
/// Jerk is taken over this window of measured acceleration.
const JERK_WINDOW_S: f64 = 0.1;
/// Below this speed comfort is not judged: a car stopping on its brakes has a jerk spike at the
/// instant it stops, and ISO 15622 puts its jerk limit on driving at speed.
const COMFORT_MIN_SPEED_MPS: f64 = 2.0;
/// The first moments of a run belong to the simulator: until the controller's first command
/// arrives the ego cruises (realtime runs), so the step to the controller's acceleration is
/// the handover, not the controller's comfort. Jerk is judged from here on.
const HANDOVER_S: f64 = 0.2;

#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct Check {
    pub name: String,
    pub value: Option<f64>,
    pub aim: String,
    pub pass: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
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
    /// The same as a share of the comfort limit at the speed it happened (1: at the limit).
    pub max_decel_share: f64,
    /// Outside emergencies and at speed, except while easing off braking.
    pub max_jerk_mps3: f64,
    /// While easing off braking (decelerating less and less), outside emergencies.
    pub max_release_jerk_mps3: f64,
    pub emergency_s: f64,
    pub max_decel_in_emergency_mps2: f64,
    /// Emergencies with no vehicle in the ego's lane (ground truth) that needed one.
    pub unwarranted_emergencies: u64,
    /// Seconds of braking beyond 1 m/s2 with nothing in the lane within twice the time gap.
    pub phantom_braking_s: f64,
    /// Those seconds as events: stretches of phantom braking, PHANTOM_EVENT_GAP_S apart at
    /// least (the rate a sweep reports per 1,000 km).
    pub phantom_braking_events: u64,
    /// How far the ego drove, metres (the sweep's rates are per distance).
    pub distance_m: f64,
    /// Seconds standing still with nothing ahead to wait for.
    pub standstill_for_nothing_s: f64,
    /// Settled behind a lead that holds its speed (within 0.3 m/s for 10 s): the largest
    /// difference between the ego's and the lead's acceleration.
    pub max_accel_swing_mps2: Option<f64>,
    /// Collisions among traffic vehicles (not the ego's; from the simulator's report).
    pub traffic_collisions: u64,
    /// The slowest answer to a lead braking beyond the comfort limit: from the moment it did
    /// to the ACC asking for the deceleration stopping behind it needs; None without one.
    pub hard_braking_response_s: Option<f64>,
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
    max_decel_share: f64,
    max_jerk: f64,
    max_release_jerk: f64,
    max_em_decel: f64,
    /// Start of the current stretch with the same truth lead, and of the current stretch in
    /// speed mode at the same set speed: (lead id or set speed, sample index).
    lead_since: Option<(u32, usize)>,
    speed_since: Option<(f64, usize)>,
    /// What a driver feels.
    feel: Feel,
    hard: HardBraking,
}

/// A lead braking beyond the comfort limit, and how soon the ACC answered.
#[derive(Default)]
struct HardBraking {
    episode: Option<Episode>,
    worst_s: Option<f64>,
}

/// One lead braking beyond the comfort limit, under way.
#[derive(Clone, Copy)]
struct Episode {
    lead_id: u32,
    from_s: f64,
    /// The most it has needed of the ego so far (m/s2).
    most_needed_mps2: f64,
    answered: bool,
}

impl HardBraking {
    fn record(&mut self, response_s: f64) {
        self.worst_s = Some(self.worst_s.map_or(response_s, |w: f64| w.max(response_s)));
    }

    /// Ends the episode at `t_s`: one never answered counts its whole length, if it needed
    /// real braking.
    fn end(&mut self, t_s: f64) {
        if let Some(e) = self.episode.take().filter(|e| !e.answered && e.most_needed_mps2 > PHANTOM_DECEL_MPS2) {
            self.record(t_s - e.from_s);
        }
    }
}

/// The true lead's acceleration at each sample, over `lag` samples of the same lead.
fn lead_accelerations(s: &[Sample], lag: usize) -> Vec<Option<f64>> {
    (0..s.len())
        .map(|i| {
            let (x, p) = (&s[i], &s[i.checked_sub(lag)?]);
            if x.truth?.id != p.truth?.id {
                return None;
            }
            Some((x.lead_speed_mps()? - p.lead_speed_mps()?) / (x.t_s - p.t_s).max(1e-6))
        })
        .collect()
}

/// The deceleration (positive) that stops the ego HARD_BRAKING_MARGIN_M behind where a lead
/// braking at `lead_accel_mps2` stops, or matches its speed short of it (the truth's view).
fn needed_behind(tl: &TruthLead, ego_speed_mps: f64, lead_accel_mps2: f64) -> f64 {
    let room = (tl.gap_m - HARD_BRAKING_MARGIN_M).max(0.1);
    let lead_speed = tl.speed_mps;
    if lead_accel_mps2 < -0.1 {
        let lead_stop = lead_speed * lead_speed / (2.0 * -lead_accel_mps2);
        ego_speed_mps * ego_speed_mps / (2.0 * (room + lead_stop))
    } else {
        let closing = (-tl.relative_speed_mps).max(0.0);
        closing * closing / (2.0 * room)
    }
}

/// Braking and stopping without cause, emergencies without need, swings while following.
#[derive(Default)]
struct Feel {
    unwarranted_emergencies: u64,
    /// The emergency under way: whether a vehicle has warranted it yet.
    emergency: Option<bool>,
    /// When a vehicle last needed an emergency, and was last near enough to brake for.
    last_needed_t: Option<f64>,
    last_near_t: Option<f64>,
    last_ahead_t: Option<f64>,
    phantom_s: f64,
    phantom_events: u64,
    /// The last sample of phantom braking.
    last_phantom_t: Option<f64>,
    standstill_s: f64,
    /// Behind a lead that has held its speed for SETTLED_S: |ego's - lead's acceleration|.
    max_swing: Option<f64>,
}

impl Feel {
    /// A vehicle in the ego's lane at sample `x` (its acceleration when known): when it last
    /// needed an emergency, was near enough to brake for, was just ahead.
    fn vehicle(&mut self, x: &Sample, tl: &TruthLead, lead_accel: Option<f64>, standstill_m: f64) {
        let f = self;
        let closing = -tl.relative_speed_mps;
        // A lead braking beyond the comfort limit warrants an emergency when stopping behind
        // it needs real braking.
        // What stopping behind a braking lead needs, were it to brake on to a stop.
        let braking_need = lead_accel.filter(|a| *a < 0.0).map_or(0.0, |a| needed_behind(tl, x.speed_mps, a));
        let hard = lead_accel.is_some_and(|a| a < -aims::MAX_DECEL_MPS2) && braking_need > PHANTOM_DECEL_MPS2;
        if hard
            || ttc(tl).is_some_and(|t| t < WARRANTED_TTC_S)
            || tl.gap_m < standstill_m + 0.5 * x.time_gap_s * x.speed_mps
        {
            f.last_needed_t = Some(x.t_s);
        }
        // Near enough to brake for: within twice the time gap, or closing so fast that
        // matching its speed short of the standstill distance needs real braking (a
        // stopped car far ahead at motorway speed), or braking so that stopping behind it
        // would need real braking (a truck 120 m ahead at 30 m/s braking at 5 m/s2: its
        // emergency was warranted, the braking in it and just before read as phantom; one
        // 200 m ahead braking at 1 m/s2 needs 0.7 and is not braked for).
        let room = (tl.gap_m - standstill_m).max(0.1);
        let needed = if closing > 0.0 { closing * closing / (2.0 * room) } else { 0.0 };
        if braking_need > PHANTOM_DECEL_MPS2
            || tl.gap_m <= standstill_m + 2.0 * x.time_gap_s * x.speed_mps
            || needed >= WARRANTED_BRAKING_MPS2
        {
            f.last_near_t = Some(x.t_s);
        }
        if tl.gap_m <= standstill_m + STANDSTILL_CLEAR_M {
            f.last_ahead_t = Some(x.t_s);
        }
    }
}

/// Time to collision with the true lead, when it closes in (faster than 0.1 m/s).
fn ttc(tl: &TruthLead) -> Option<f64> {
    let closing = -tl.relative_speed_mps;
    (closing > 0.1).then(|| tl.gap_m.max(0.0) / closing)
}

/// Steady following: the same lead for 2 x STEADY_S (time to settle), its speed within 1 m/s
/// over the last STEADY_S of `stretch`, which ends at `now`, and the ego at its speed (within
/// 1 m/s): closing on a car that stood still all along is an approach, not following.
fn steady_lead(stretch: &[Sample], now: &Sample) -> bool {
    if now.t_s - stretch[0].t_s < 2.0 * STEADY_S
        || now.truth.is_none_or(|t| t.relative_speed_mps.abs() >= FOLLOWING_BAND_MPS)
    {
        return false;
    }
    let lead_speed = |w: &Sample| w.lead_speed_mps().unwrap_or(w.speed_mps);
    // Samples are in time order: the window starts where a binary search finds it (a scan
    // from the stretch's start made an hour behind one lead quadratic).
    let start = stretch.partition_point(|w| w.t_s < now.t_s - STEADY_S);
    let (lo, hi) =
        stretch[start..].iter().map(lead_speed).fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    hi - lo < FOLLOWING_BAND_MPS
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
        if let Some(ttc) = ttc(&tl) {
            self.min_ttc = Some(self.min_ttc.map_or(ttc, |m| m.min(ttc)));
        }
        if self.lead_since.is_none_or(|(id, _)| id != tl.id) {
            self.lead_since = Some((tl.id, i));
        }
        let from = self.lead_since.map_or(i, |(_, from)| from);
        // The ego too has kept to the lead's speed (within FOLLOWING_BAND_MPS) for SETTLED_S:
        // the tail of an approach or of a catch-up is no following yet (after a lead moved off
        // from a stop ahead of the ego, the gap still closing from 30 to 24 m at 1 m/s read as
        // a 0.06-0.09 s time-gap error with both perceptions).
        // (Scanned last: ten seconds of samples at each one.)
        let past = s[from + s[from..=i].partition_point(|w| w.t_s < x.t_s - SETTLED_S)..=i].iter();
        let kept = || past.clone().all(|w| w.truth.is_some_and(|t| t.relative_speed_mps.abs() < FOLLOWING_BAND_MPS));
        if x.mode == AccMode::Follow && x.speed_mps > 3.0 && steady_lead(&s[from..=i], x) && kept() {
            self.gap_errors.push((tl.gap_m - standstill_m) / x.speed_mps - x.time_gap_s);
            // The lead's acceleration over the last LEAD_ACCEL_WINDOW_S, against the ego's.
            let lead_speed = |w: &Sample| w.lead_speed_mps().unwrap_or(w.speed_mps);
            // Settled behind a lead holding its speed: the ego's acceleration stays with the
            // lead's (a limit cycle shows here; following a lead's speed changes does not).
            // (The trace is judged whole: the lead must also hold its speed a little beyond now,
            // so the onset of its next change, which the ego answers at once, is not counted;
            // nor is a lead about to leave the lane, whose next change is not seen: one
            // speeding up as it moved out read as a 0.4 m/s2 swing.)
            // With the ego kept to its speed (above): the end of an approach from 30 to 20 m/s,
            // easing at 0.3 m/s2 as the gap closes on the time gap, is not a swing.
            let ahead = s[i..].iter().take_while(|w| w.t_s <= x.t_s + SETTLED_AHEAD_S);
            let stays = ahead.clone().all(|w| w.truth.is_some_and(|t| t.id == tl.id));
            let (lo, hi) =
                past.chain(ahead).map(lead_speed).fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            let settled = stays && x.t_s - s[from].t_s >= SETTLED_S + STEADY_S && hi - lo <= SETTLED_SPEED_BAND_MPS;
            if let Some(p) = s[from..i].iter().rev().find(|p| x.t_s - p.t_s >= LEAD_ACCEL_WINDOW_S).filter(|_| settled)
            {
                let lead_accel = (lead_speed(x) - lead_speed(p)) / (x.t_s - p.t_s);
                let swing = (x.accel_mps2 - lead_accel).abs();
                self.feel.max_swing = Some(self.feel.max_swing.map_or(swing, |m: f64| m.max(swing)));
            }
        }
    }

    /// What a driver would feel at sample `i` (`dt` apart): emergencies nothing in the lane
    /// warranted, braking beyond PHANTOM_DECEL_MPS2 with nothing within twice the time gap,
    /// standing still with nothing ahead.
    fn feel(&mut self, s: &[Sample], i: usize, dt: f64, trace: &Trace, lead_accel: Option<f64>) {
        let (x, standstill_m) = (&s[i], trace.standstill_m);
        // What the scenario declares (generated scenarios do) overrides the reading of the
        // truth: no braking where its lane stays clear, no emergency where comfort suffices.
        let (clear_lane, comfort_suffices) = match trace.braking_warranted {
            Some(Warranted::None) => (true, true),
            Some(Warranted::Comfort) => (false, true),
            Some(Warranted::Emergency) | None => (false, false),
        };
        let f = &mut self.feel;
        // The true lead, and the next vehicle in the lane beyond it (one the lead hides from a
        // camera, but not from the truth: a car standing beyond a lead about to move out).
        if let Some(tl) = x.truth {
            f.vehicle(x, &tl, lead_accel, standstill_m);
        }
        if let Some(tl) = x.beyond {
            f.vehicle(x, &tl, None, standstill_m);
        }
        let since = |t: Option<f64>| t.map_or(f64::INFINITY, |t| x.t_s - t);
        // Emergencies: judged at their end, warranted by need from just before their start.
        if x.mode == AccMode::Emergency {
            let needed = since(f.last_needed_t) <= EMERGENCY_LOOKBACK_S && !comfort_suffices;
            f.emergency = Some(f.emergency.unwrap_or(false) || needed);
        } else if let Some(warranted) = f.emergency.take() {
            f.unwarranted_emergencies += u64::from(!warranted);
        }
        // Braking for nothing: not while slowing to a lower set speed or on stale inputs (a
        // fault, said by a warning), nor just after a vehicle left the lane.
        let slowing_to_set = x.mode == AccMode::Speed && x.speed_mps > x.set_speed_mps + 0.5;
        let deliberate = matches!(x.mode, AccMode::Off | AccMode::Stale) || slowing_to_set;
        if x.accel_mps2 < -PHANTOM_DECEL_MPS2
            && x.speed_mps > COMFORT_MIN_SPEED_MPS
            && !deliberate
            && (clear_lane || since(f.last_near_t) > PHANTOM_GRACE_S)
        {
            f.phantom_s += dt;
            f.phantom_events += u64::from(since(f.last_phantom_t) > PHANTOM_EVENT_GAP_S);
            f.last_phantom_t = Some(x.t_s);
        }
        if x.speed_mps < 0.5
            && x.mode != AccMode::Off
            && x.set_speed_mps > 1.0
            && since(f.last_ahead_t) > STANDSTILL_GRACE_S
            && x.t_s - s[0].t_s > STANDSTILL_GRACE_S
        {
            f.standstill_s += dt;
        }
    }

    /// A lead braking beyond the comfort limit at sample `x` (its acceleration `lead_accel`):
    /// when it starts, and when the ACC's target first asks for what stopping behind it needs.
    fn hard_braking(&mut self, x: &Sample, lead_accel: Option<f64>) {
        let h = &mut self.hard;
        let Some((tl, a)) = x.truth.zip(lead_accel).filter(|(tl, _)| h.episode.is_none_or(|e| e.lead_id == tl.id))
        else {
            h.end(x.t_s);
            return;
        };
        if h.episode.is_none() && a < -aims::MAX_DECEL_MPS2 {
            h.episode = Some(Episode { lead_id: tl.id, from_s: x.t_s, most_needed_mps2: 0.0, answered: false });
        }
        let Some(mut e) = h.episode else { return };
        if a > -PHANTOM_DECEL_MPS2 {
            h.end(x.t_s);
            return;
        }
        let needed = needed_behind(&tl, x.speed_mps, a);
        if !e.answered && x.target_accel_mps2 <= -NEED_SHARE * needed {
            e.answered = true;
            h.record(x.t_s - e.from_s);
        }
        e.most_needed_mps2 = e.most_needed_mps2.max(needed);
        h.episode = Some(e);
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
        let limit = comfort_decel_at(x.speed_mps, aims::MAX_DECEL_MPS2, aims::MAX_DECEL_LOW_SPEED_MPS2);
        self.max_decel_share = self.max_decel_share.max(-x.accel_mps2 / limit);
        if i >= jerk_lag
            && s[i - jerk_lag].speed_mps >= COMFORT_MIN_SPEED_MPS
            && s[i - jerk_lag].t_s - s[0].t_s >= HANDOVER_S
        {
            let p = &s[i - jerk_lag];
            let j = (x.accel_mps2 - p.accel_mps2) / (x.t_s - p.t_s).max(1e-6);
            if p.accel_mps2 < 0.0 && j > 0.0 {
                self.max_release_jerk = self.max_release_jerk.max(j);
            } else {
                self.max_jerk = self.max_jerk.max(j.abs());
            }
        }
    }

    /// Pass or fail against the aims.
    fn checks(&self, collisions: u64, time_gap_rms: Option<f64>, min_gap_aim_m: Option<f64>) -> Vec<Check> {
        let tol = 1.0 + aims::COMFORT_TOLERANCE;
        let comfort = |name: &str, value: f64, aim: f64| Check {
            name: name.into(),
            value: Some(value),
            aim: format!("<= {aim} (+{:.0}%)", aims::COMFORT_TOLERANCE * 100.0),
            pass: value <= aim * tol,
        };
        let mut checks = vec![
            Check { name: "collisions".into(), value: Some(collisions as f64), aim: "0".into(), pass: collisions == 0 },
            match min_gap_aim_m {
                Some(aim) => Check {
                    name: "min gap (m)".into(),
                    value: self.min_gap,
                    aim: format!(">= {aim} (the scenario's)"),
                    pass: self.min_gap.is_none_or(|g| g >= aim),
                },
                None => Check {
                    name: "min gap (m)".into(),
                    value: self.min_gap,
                    aim: "> 0".into(),
                    pass: self.min_gap.is_none_or(|g| g > 0.0),
                },
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
        checks.push(Check {
            name: format!(
                "max decel outside emergencies, x the comfort limit at its speed ({} m/s2 from {} m/s, {} at {} m/s and below)",
                aims::MAX_DECEL_MPS2,
                COMFORT_HIGH_SPEED_MPS,
                aims::MAX_DECEL_LOW_SPEED_MPS2,
                COMFORT_LOW_SPEED_MPS
            ),
            value: Some(self.max_decel_share),
            aim: format!("<= 1 (+{:.0}%)", aims::COMFORT_TOLERANCE * 100.0),
            pass: self.max_decel_share <= tol,
        });
        // Jerk is judged strictly: the controller's own limit sits below the aim, with room for
        // the vehicle's response. Easing off braking has an aim of its own.
        checks.push(Check {
            name: "max jerk outside emergencies (m/s3)".into(),
            value: Some(self.max_jerk),
            aim: format!("<= {}", aims::MAX_JERK_MPS3),
            pass: self.max_jerk <= aims::MAX_JERK_MPS3,
        });
        checks.push(Check {
            name: "max jerk easing off braking (m/s3)".into(),
            value: Some(self.max_release_jerk),
            aim: format!("<= {}", aims::MAX_RELEASE_JERK_MPS3),
            pass: self.max_release_jerk <= aims::MAX_RELEASE_JERK_MPS3,
        });
        // What a driver feels: each must be zero.
        let f = &self.feel;
        let none = |name: &str, value: f64| Check {
            name: name.into(),
            value: Some(value),
            aim: "0".into(),
            pass: value == 0.0,
        };
        checks.push(none("unwarranted emergencies", f.unwarranted_emergencies as f64));
        checks.push(none("phantom braking (s)", f.phantom_s));
        checks.push(none("standstill with nothing ahead (s)", f.standstill_s));
        if let Some(swing) = f.max_swing {
            checks.push(Check {
                name: "acceleration swing in steady following (m/s2)".into(),
                value: Some(swing),
                aim: format!("<= {}", aims::MAX_ACCEL_SWING_MPS2),
                pass: swing <= aims::MAX_ACCEL_SWING_MPS2,
            });
        }
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
        let near_emergency = |t: f64| {
            let first = emergency_times.partition_point(|&e| e < t - EMERGENCY_MARGIN_S.1);
            emergency_times.get(first).is_some_and(|&e| e <= t + EMERGENCY_MARGIN_S.0)
        };
        let samples_in = |window_s: f64| (window_s / dt.max(1e-6)).round().max(1.0) as usize;
        let jerk_lag = samples_in(JERK_WINDOW_S);
        let lead_accel = lead_accelerations(s, samples_in(HARD_BRAKING_WINDOW_S));
        let mut tally = Tally::default();
        for i in 0..s.len() {
            tally.lead(s, i, trace.standstill_m);
            tally.speed_mode(s, i);
            tally.comfort(s, i, jerk_lag, near_emergency(s[i].t_s));
            tally.feel(s, i, dt, trace, lead_accel[i]);
            tally.hard_braking(&s[i], lead_accel[i]);
        }
        tally.hard.end(s.last().map_or(0.0, |x| x.t_s));
        if let Some(warranted) = tally.feel.emergency.take() {
            tally.feel.unwarranted_emergencies += u64::from(!warranted);
        }
        let time_gap_rms = rms(&tally.gap_errors);
        let checks = tally.checks(trace.collisions, time_gap_rms, trace.min_gap_aim_m);
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
            max_decel_share: tally.max_decel_share,
            max_jerk_mps3: tally.max_jerk,
            max_release_jerk_mps3: tally.max_release_jerk,
            emergency_s: emergency_times.len() as f64 * dt,
            max_decel_in_emergency_mps2: tally.max_em_decel,
            unwarranted_emergencies: tally.feel.unwarranted_emergencies,
            phantom_braking_s: tally.feel.phantom_s,
            phantom_braking_events: tally.feel.phantom_events,
            distance_m: s.iter().map(|x| x.speed_mps * dt).sum(),
            standstill_for_nothing_s: tally.feel.standstill_s,
            max_accel_swing_mps2: tally.feel.max_swing,
            traffic_collisions: trace.traffic_collisions,
            hard_braking_response_s: tally.hard.worst_s,
            pass: checks.iter().all(|c| c.pass),
            checks,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.01;

    /// A trace at 100 Hz from `f(t)` = (speed, accel, mode, truth lead as (gap, relative speed)).
    fn trace(seconds: f64, f: impl Fn(f64) -> (f64, f64, AccMode, Option<(f64, f64)>)) -> Trace {
        let samples = (0..(seconds / DT) as usize)
            .map(|i| {
                let t_s = i as f64 * DT;
                let (speed_mps, accel_mps2, mode, truth) = f(t_s);
                Sample {
                    t_s,
                    speed_mps,
                    accel_mps2,
                    mode,
                    target_accel_mps2: accel_mps2,
                    set_speed_mps: 30.0,
                    time_gap_s: 1.8,
                    acc_gap_m: truth.map(|t| t.0),
                    truth: truth.map(|(gap_m, relative_speed_mps)| TruthLead {
                        id: 1,
                        gap_m,
                        relative_speed_mps,
                        speed_mps: speed_mps + relative_speed_mps,
                    }),
                    beyond: None,
                }
            })
            .collect();
        Trace { standstill_m: 5.0, samples, ..Default::default() }
    }

    fn failed(m: &Metrics) -> Vec<&str> {
        m.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect()
    }

    #[test]
    fn deceleration_is_judged_against_the_comfort_limit_of_its_speed() {
        // 4.5 m/s2 for a car 20 m ahead: within comfort at 8 m/s (limit 4.7), not at 25 m/s (3.5).
        let braking = |t: f64| if (10.0..11.0).contains(&t) { -4.5 } else { 0.0 };
        let at = |v: f64| Metrics::of(&trace(20.0, |t| (v, braking(t), AccMode::Follow, Some((20.0, 0.0)))));
        let (slow, fast) = (at(8.0), at(25.0));
        assert_eq!((slow.max_decel_mps2, fast.max_decel_mps2), (4.5, 4.5));
        assert!((slow.max_decel_share - 4.5 / 4.7).abs() < 1e-9, "{}", slow.max_decel_share);
        let decel_failed = |m: &Metrics| failed(m).iter().any(|c| c.starts_with("max decel outside emergencies"));
        assert!(!decel_failed(&slow), "{:?}", failed(&slow));
        assert!(decel_failed(&fast), "{:?}", failed(&fast));
    }

    #[test]
    fn easing_off_braking_is_judged_on_its_own_jerk_aim() {
        // Braking at 3 m/s2 at 25 m/s, applied at 2 m/s3, then released at `release` m/s3.
        let run = |release: f64| {
            Metrics::of(&trace(20.0, move |t| {
                let a =
                    if t < 10.0 { -(2.0 * (t - 8.5)).clamp(0.0, 3.0) } else { (-3.0 + release * (t - 10.0)).min(0.0) };
                (25.0, a, AccMode::Follow, Some((40.0, 0.0)))
            }))
        };
        let (quick, abrupt) = (run(8.0), run(30.0));
        assert!((quick.max_release_jerk_mps3 - 8.0).abs() < 0.5, "{}", quick.max_release_jerk_mps3);
        assert!(quick.max_jerk_mps3 <= 2.0 + 1e-9, "{}", quick.max_jerk_mps3);
        assert!(failed(&quick).is_empty(), "{:?}", failed(&quick));
        assert!(failed(&abrupt).contains(&"max jerk easing off braking (m/s3)"), "{:?}", failed(&abrupt));
        // Applying the brake that fast is still judged on the comfort jerk.
        let applied = Metrics::of(&trace(20.0, |t| {
            (25.0, -(8.0 * (t - 10.0)).clamp(0.0, 3.0), AccMode::Follow, Some((40.0, 0.0)))
        }));
        assert!(failed(&applied).contains(&"max jerk outside emergencies (m/s3)"), "{:?}", failed(&applied));
    }

    #[test]
    fn braking_with_nothing_in_the_lane_is_phantom_braking() {
        let braking = |t: f64| if (10.0..12.0).contains(&t) { -2.0 } else { 0.0 };
        let empty = Metrics::of(&trace(30.0, |t| (25.0, braking(t), AccMode::Follow, None)));
        assert!((empty.phantom_braking_s - 2.0).abs() < 0.05, "{}", empty.phantom_braking_s);
        assert!(failed(&empty).contains(&"phantom braking (s)"));
        // The same braking for a car 40 m ahead, or for a stopped car 150 m ahead at 25 m/s
        // (stopping short of it needs 2.2 m/s2), is warranted.
        let near = Metrics::of(&trace(30.0, |t| (25.0, braking(t), AccMode::Follow, Some((40.0, 0.0)))));
        let stopped = Metrics::of(&trace(30.0, |t| (25.0, braking(t), AccMode::Follow, Some((150.0, -25.0)))));
        assert_eq!((near.phantom_braking_s, stopped.phantom_braking_s), (0.0, 0.0));
        // A lead beyond twice the time gap braking from t = 9 s: at 4 m/s2 120 m ahead,
        // stopping behind it needs real braking; at 1 m/s2 200 m ahead, it does not.
        let lead_braking = |gap: f64, decel: f64| {
            Metrics::of(&trace(30.0, move |t| {
                let rel = -decel * (t - 9.0).clamp(0.0, 3.0);
                (25.0, braking(t), AccMode::Follow, Some((gap, rel)))
            }))
        };
        assert_eq!(lead_braking(120.0, 4.0).phantom_braking_s, 0.0);
        let gentle = lead_braking(200.0, 1.0).phantom_braking_s;
        assert!((gentle - 2.0).abs() < 0.05, "{gentle}");
        // Slowing to a lower set speed is not phantom braking.
        let slowing = Metrics::of(&trace(30.0, |t| (35.0, braking(t), AccMode::Speed, None)));
        assert_eq!(slowing.phantom_braking_s, 0.0);
    }

    #[test]
    fn an_emergency_nothing_in_the_lane_needed_is_unwarranted() {
        let mode = |t: f64| if (10.0..11.0).contains(&t) { AccMode::Emergency } else { AccMode::Follow };
        let far = Metrics::of(&trace(20.0, |t| (25.0, 0.0, mode(t), Some((80.0, 0.0)))));
        assert_eq!(far.unwarranted_emergencies, 1);
        assert!(failed(&far).contains(&"unwarranted emergencies"));
        let closing = Metrics::of(&trace(20.0, |t| (25.0, 0.0, mode(t), Some((30.0, -15.0)))));
        assert_eq!(closing.unwarranted_emergencies, 0);
    }

    #[test]
    fn phantom_braking_is_counted_in_events_and_the_distance_driven_is_kept() {
        // Brakes at 10-11 s and 11.5-12 s: one event (closer than PHANTOM_EVENT_GAP_S); a
        // third at 20-21 s: another.
        let braking = |t: f64| {
            if (10.0..11.0).contains(&t) || (11.5..12.0).contains(&t) || (20.0..21.0).contains(&t) {
                -2.0
            } else {
                0.0
            }
        };
        let m = Metrics::of(&trace(30.0, |t| (25.0, braking(t), AccMode::Follow, None)));
        assert_eq!(m.phantom_braking_events, 2);
        assert!((m.phantom_braking_s - 2.5).abs() < 0.05, "{}", m.phantom_braking_s);
        assert!((m.distance_m - 750.0).abs() < 1.0, "{}", m.distance_m);
    }

    #[test]
    fn what_a_scenario_declares_warranted_overrides_the_reading_of_the_truth() {
        // Braking for a car 40 m ahead reads as warranted; the scenario says its lane stays
        // clear (the car is in the next lane, say, and the judge's truth lead is wrong).
        let braking = |t: f64| if (10.0..12.0).contains(&t) { -2.0 } else { 0.0 };
        let mut near = trace(30.0, |t| (25.0, braking(t), AccMode::Follow, Some((40.0, 0.0))));
        assert_eq!(Metrics::of(&near).phantom_braking_s, 0.0);
        near.braking_warranted = Some(Warranted::None);
        let declared = Metrics::of(&near);
        assert!((declared.phantom_braking_s - 2.0).abs() < 0.05, "{}", declared.phantom_braking_s);
        assert_eq!(declared.phantom_braking_events, 1);
        near.braking_warranted = Some(Warranted::Comfort);
        assert_eq!(Metrics::of(&near).phantom_braking_s, 0.0);
        // An emergency for a car closing fast: warranted, unless comfort braking sufficed.
        let mode = |t: f64| if (10.0..11.0).contains(&t) { AccMode::Emergency } else { AccMode::Follow };
        let mut closing = trace(20.0, |t| (25.0, 0.0, mode(t), Some((30.0, -15.0))));
        closing.braking_warranted = Some(Warranted::Emergency);
        assert_eq!(Metrics::of(&closing).unwarranted_emergencies, 0);
        closing.braking_warranted = Some(Warranted::Comfort);
        assert_eq!(Metrics::of(&closing).unwarranted_emergencies, 1);
    }

    #[test]
    fn braking_for_a_vehicle_standing_beyond_the_lead_is_warranted() {
        // The lead pulls away 60 m ahead (beyond twice the time gap at 15 m/s); a car stands
        // in the lane 95 m ahead beyond it: stopping short of it needs 1.3 m/s2.
        let braking = |t: f64| if (10.0..12.0).contains(&t) { -1.2 } else { 0.0 };
        let mut run = trace(30.0, |t| (15.0, braking(t), AccMode::Follow, Some((60.0, 3.0))));
        assert!(Metrics::of(&run).phantom_braking_s > 1.9, "the lead alone does not warrant it");
        for x in &mut run.samples {
            x.beyond = Some(TruthLead { id: 2, gap_m: 95.0, relative_speed_mps: -15.0, speed_mps: 0.0 });
        }
        assert_eq!(Metrics::of(&run).phantom_braking_s, 0.0);
    }

    #[test]
    fn standing_still_with_nothing_ahead_is_stopping_for_nothing() {
        let empty = Metrics::of(&trace(20.0, |_| (0.0, 0.0, AccMode::Follow, None)));
        assert!(empty.standstill_for_nothing_s > 15.0, "{}", empty.standstill_for_nothing_s);
        assert!(failed(&empty).contains(&"standstill with nothing ahead (s)"));
        let queue = Metrics::of(&trace(20.0, |_| (0.0, 0.0, AccMode::Follow, Some((6.0, 0.0)))));
        assert_eq!(queue.standstill_for_nothing_s, 0.0);
    }

    #[test]
    fn the_time_gap_is_judged_once_the_ego_keeps_to_the_leads_speed() {
        // A lead at 20 m/s held 4 m beyond the 1.8 s gap (0.2 s too far): the ego closes at
        // 3 m/s until `caught_s`, then at 0.8 m/s (within the following band) to the end.
        let run = |caught_s: f64, seconds: f64| {
            Metrics::of(&trace(seconds, |t| {
                let rel = if t < caught_s { -3.0 } else { -0.8 };
                (20.0 - rel, 0.0, AccMode::Follow, Some((5.0 + 1.8 * (20.0 - rel) + 4.0, rel)))
            }))
        };
        // Kept to its speed for 8 s: the tail of a catch-up, not judged.
        let tail = run(22.0, 30.0);
        assert_eq!(tail.time_gap_rms_error_s, None);
        // For 18 s: following, 0.2 s off, which fails.
        let kept = run(22.0, 40.0);
        let e = kept.time_gap_rms_error_s.expect("judged");
        assert!((e - 4.0 / 20.8).abs() < 0.01, "{e}");
        assert!(failed(&kept).iter().any(|c| c.starts_with("time-gap RMS")), "{:?}", failed(&kept));
    }

    #[test]
    fn a_limit_cycle_behind_a_steady_lead_is_an_acceleration_swing() {
        // The ego's speed swings around the lead's 25 m/s every 5 s; the lead holds its speed.
        let cycling = |amplitude: f64| {
            move |t: f64| {
                let w = std::f64::consts::TAU / 5.0;
                let accel = amplitude * (w * t).sin();
                let speed = 25.0 - amplitude / w * (w * t).cos();
                (speed, accel, AccMode::Follow, Some((50.0, 25.0 - speed)))
            }
        };
        let cycle = Metrics::of(&trace(60.0, cycling(1.0)));
        assert!(cycle.max_accel_swing_mps2.is_some_and(|s| s > 0.9), "{:?}", cycle.max_accel_swing_mps2);
        assert!(failed(&cycle).contains(&"acceleration swing in steady following (m/s2)"));
        let calm = Metrics::of(&trace(60.0, cycling(0.05)));
        assert!(calm.max_accel_swing_mps2.is_some_and(|s| s < 0.1), "{:?}", calm.max_accel_swing_mps2);
        assert!(!failed(&calm).contains(&"acceleration swing in steady following (m/s2)"));
        // A lead that speeds up as it moves out of the lane at 50.3 s: its change is not seen
        // through, so the ego not following it is no swing.
        let leaving = Metrics::of(&trace(60.0, |t| {
            let lead = 25.0 + (t - 50.0).max(0.0);
            (25.0, 0.0, AccMode::Follow, (t < 50.3).then_some((50.0, lead - 25.0)))
        }));
        assert!(leaving.max_accel_swing_mps2.is_some_and(|s| s < 0.05), "{:?}", leaving.max_accel_swing_mps2);
        // The end of an approach: from 30 m/s down to a lead's 20, easing off exponentially
        // (3 s). Within 1 m/s of the lead from 36.9 s on at 0.33 m/s2: not yet settled.
        let approach = Metrics::of(&trace(60.0, |t| {
            let fade = (-(t - 30.0).max(0.0) / 3.0).exp();
            let speed = 20.0 + 10.0 * fade;
            let accel = if t > 30.0 { -10.0 / 3.0 * fade } else { 0.0 };
            (speed, accel, AccMode::Follow, Some((60.0, 20.0 - speed)))
        }));
        assert!(approach.max_accel_swing_mps2.is_some_and(|s| s < 0.05), "{:?}", approach.max_accel_swing_mps2);
    }

    /// A lead at 30 m/s, 59 m ahead of an ego holding 30 m/s, braking at 7 m/s2 from t = 10 s;
    /// the ego's target from `answer(t)`, its mode from `mode(t)`.
    fn hard_braking_trace(answer: impl Fn(f64) -> f64, mode: impl Fn(f64) -> AccMode) -> Trace {
        let lead_speed = |t: f64| if t > 10.0 { (30.0 - 7.0 * (t - 10.0)).max(0.0) } else { 30.0 };
        // The ego keeps 30 m/s: the gap shrinks by what the lead's braking costs it (the trace
        // ends before the lead stops).
        let gap = |t: f64| {
            let dt = (t - 10.0).max(0.0);
            59.0 - 3.5 * dt * dt
        };
        trace(14.0, |t| (30.0, answer(t), mode(t), Some((gap(t), lead_speed(t) - 30.0))))
    }

    #[test]
    fn the_answer_to_a_hard_braking_lead_is_timed_from_its_braking_to_the_need_met() {
        let follow = |_: f64| AccMode::Follow;
        // Asking for 6 m/s2 from t = 10.3 s: the lead braked beyond 3.5 m/s2 at about 10.05 s.
        let prompt = Metrics::of(&hard_braking_trace(|t| if t >= 10.3 { -6.0 } else { 0.0 }, follow));
        let r = prompt.hard_braking_response_s.expect("an episode");
        assert!((0.2..=0.3).contains(&r), "{r}");
        // Asking for 1 m/s2 only: never what stopping behind it needs, so the whole episode.
        let timid = Metrics::of(&hard_braking_trace(|t| if t >= 10.3 { -1.0 } else { 0.0 }, follow));
        assert!(timid.hard_braking_response_s.is_some_and(|r| r > 3.5), "{:?}", timid.hard_braking_response_s);
        // A lead holding its speed is no episode.
        let steady = Metrics::of(&trace(14.0, |_| (30.0, 0.0, AccMode::Follow, Some((59.0, 0.0)))));
        assert_eq!(steady.hard_braking_response_s, None);
    }

    #[test]
    fn an_emergency_for_a_lead_braking_beyond_comfort_is_warranted() {
        let emergency = |t: f64| if (10.2..12.0).contains(&t) { AccMode::Emergency } else { AccMode::Follow };
        let m = Metrics::of(&hard_braking_trace(|t| if t >= 10.2 { -6.0 } else { 0.0 }, emergency));
        assert_eq!(m.unwarranted_emergencies, 0);
        // The same emergency behind the same lead holding its speed is not.
        let steady = Metrics::of(&trace(14.0, |t| (30.0, 0.0, emergency(t), Some((59.0, 0.0)))));
        assert_eq!(steady.unwarranted_emergencies, 1);
    }
}
