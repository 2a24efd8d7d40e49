//! The decision, as one table: each hypothesis of the lead belief (`super::belief`) has a
//! need (the deceleration that keeps clear of it, and its TTC), and where that need falls
//! against the comfort envelope (what comfort braking from now on keeps clear of, at the jerk
//! limit up to each speed's limit) and the emergency envelope (what an emergency can still do
//! later) decides:
//!
//! | hypothesis | comfort command plans for it | an emergency starts when | an emergency holds while |
//! |---|---|---|---|
//! | mildest (or the revealed, the worse) | always (the law answers alone below `needed_guard_mps2`; far ahead, not closing fast and the lead not seen braking hard: eased to `far_decel_mps2`) | - | its TTC <= `release_ttc_s` or its need >= `release_share` of the comfort limit |
//! | confirmed (the same, measured over `confirm_s`) | - | *beyond comfort*: TTC < `release_ttc_s`, need above this speed's comfort limit, comfort braking does not keep clear, and it cannot wait; or *closing fast*: TTC < `brake_ttc_s` while braking less than the need by `under_braking_s` of jerk | - |
//! | likely (while the lead brakes beyond comfort) | - | *lead braking hard*: its need (or the mildest's, the worse) > `emergency_factor` x `needed_guard_mps2` and it cannot wait | the mildest's need >= `needed_guard_mps2` |
//! | hardest (a new lead's slowest speed; lamps just lit: the comfort limit) | with the mildest, the worse, where comfort braking copes with it; else the mildest alone | - | - |
//! | hardest not yet (a new lead far ahead, cheap to wait for) | only the revealed | - | - |
//!
//! "It cannot wait": comfort braking for `wait_s` more and then an emergency at
//! `planned_emergency_mps2` would not keep the standstill distance either. An emergency
//! therefore comes at the last responsible moment: a lead braking hard often stops braking
//! before it stops, and then comfort braking was enough. At standstill an emergency ends. Only
//! what has been measured in more than one frame starts one.

use super::belief::{Hardest, Hypotheses, LeadBelief};
use super::settings::AccSettings;
use super::threat::{threat, Threat, MIN_ROOM_M};

/// Emergency or not, and the lead last found braking beyond the comfort limit.
#[derive(Debug, Clone, Default)]
pub(super) struct Decision {
    pub(super) emergency: bool,
    /// The lead last found braking beyond the comfort limit, while it still is.
    pub(super) hard_lead: Option<u32>,
}

/// What a decision reads this step besides the hypotheses.
pub(super) struct Now<'a> {
    pub(super) settings: &'a AccSettings,
    /// The ego's speed.
    pub(super) speed_mps: f64,
    /// The command of the last step (negative: braking).
    pub(super) accel_cmd_mps2: f64,
    /// The ego's time (simulated).
    pub(super) t_s: f64,
}

/// The least braking the comfort command gives (the table's second column, m/s2; None: the
/// time-gap law alone): what the plan needs once that is more than `needed_guard_mps2` (below
/// it, a lead easing off a little or the noise of its deceleration would make the car dip for
/// nothing), eased off for a plan far ahead that the ego is not closing on fast
/// ([`far_cap_mps2`]).
pub(super) fn comfort_brake_mps2(
    h: &Hypotheses,
    lead: &LeadBelief,
    s: &AccSettings,
    v: f64,
    time_gap_s: f64,
) -> Option<f64> {
    let plan = comfort_plan(h, s, v)?;
    let needed = plan.needed_decel_mps2;
    (needed > s.tuning.decision.needed_guard_mps2.get())
        .then(|| needed.min(far_cap_mps2(s, &plan, v, time_gap_s, lead)))
}

/// What comfort braking plans for: the threat, or a worse one while the lead is not yet
/// measured, where comfort braking copes with that.
fn comfort_plan(h: &Hypotheses, s: &AccSettings, v: f64) -> Option<Threat> {
    let threat = h.threat();
    match h.hardest {
        Hardest::NotYet => h.revealed,
        Hardest::Is(worse) if worse.needed_decel_mps2 <= s.limits.decel_at(v) => Some(threat.or_worse(&worse)),
        _ => Some(threat),
    }
}

impl Decision {
    /// Resets: disengaged or stale.
    pub(super) fn clear(&mut self) {
        *self = Decision::default();
    }

    /// Enters an emergency where a row of the table starts one; leaves it at standstill or
    /// where no row holds it.
    pub(super) fn update(&mut self, h: Option<&Hypotheses>, x: &Now) {
        let Some(h) = h else {
            self.emergency = false;
            return;
        };
        let t = h.threat();
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        if !self.emergency {
            if let Some(rule) = starts(h, x) {
                let (needed_decel_mps2, hard_lead) = (t.needed_decel_mps2, h.likely.is_some());
                tracing::warn!(t_s = x.t_s, ttc_s = ttc, needed_decel_mps2, hard_lead, rule, "emergency braking");
                self.emergency = true;
            }
        } else if x.speed_mps < x.settings.tuning.low_level.standstill_mps.get() || !holds(h, x.settings) {
            tracing::info!(t_s = x.t_s, ttc_s = ttc, "emergency over");
            self.emergency = false;
        }
    }
    /// Emergency deceleration: the vehicle's maximum when TTC is below full_brake_ttc_s, else
    /// `emergency_factor` times what the threat needs, and no less than stopping the standstill
    /// distance behind needs (an emergency that started at the last responsible moment has no
    /// room to spare); at least the comfort limit once the gap closes fast (TTC below
    /// brake_ttc_s; behind a hard-braking lead still far enough, the factor times the need is
    /// enough).
    pub(super) fn decel(&self, s: &AccSettings, t: &Threat, v: f64) -> f64 {
        let vehicle_max = s.vehicle.max_brake_decel_mps2;
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        if ttc < s.emergency.full_brake_ttc_s {
            return vehicle_max;
        }
        let hard_lead = self.hard_lead.is_some();
        let floor = if hard_lead && ttc >= s.emergency.brake_ttc_s { 0.0 } else { s.limits.decel_mps2 };
        let (behind_standstill, k) = (short_of_standstill(s, t), &s.tuning.threat);
        let standstill_need =
            threat(k, behind_standstill.room_m + k.margin_m.get(), v, t.lead_speed_mps, t.lead_accel_mps2);
        let need =
            (s.tuning.decision.emergency_factor.get() * t.needed_decel_mps2).max(standstill_need.needed_decel_mps2);
        need.clamp(floor, vehicle_max)
    }
}

/// The most the command brakes for a threat: a vehicle beyond `far_time_gaps` time gaps that
/// the ego is not closing on fast (matching its speed short of the standstill distance needs
/// less than `far_closing_mps2`) is answered by easing off, at most `far_decel_mps2`, unless
/// `lead` is seen braking harder than `far_braking_mps2` with its lamps lit. A lead braking
/// for a moment several time gaps ahead (following its own lead) is no reason to brake and
/// then accelerate again; one that keeps braking is soon near or closing fast, and braked for
/// in full.
fn far_cap_mps2(s: &AccSettings, t: &Threat, v: f64, time_gap_s: f64, lead: &LeadBelief) -> f64 {
    let c = &s.tuning.command;
    let gap = t.room_m + s.tuning.threat.margin_m.get();
    let room = (gap - s.standstill_m).max(MIN_ROOM_M);
    let closing = (v - t.lead_speed_mps).max(0.0);
    let far = gap > s.standstill_m + c.far_time_gaps.get() * time_gap_s * v;
    // The lead as estimated, not as comfort braking may plan for it (braking at the comfort
    // limit while its lamps are new): planned for that far ahead, a touch of the lead's pedal
    // would brake the ego hard for nothing.
    let easing = !lead.seen_braking(c.far_braking_mps2.get());
    if far && easing && closing * closing / (2.0 * room) < c.far_closing_mps2.get() {
        c.far_decel_mps2.get()
    } else {
        f64::INFINITY
    }
}

/// The threat with the standstill distance kept as well as the threat's margin (for the
/// brakes' lag and the estimate's error).
fn short_of_standstill(s: &AccSettings, t: &Threat) -> Threat {
    Threat { room_m: t.room_m - s.standstill_m, ..*t }
}

/// The row of the table that starts an emergency now, if any.
fn starts(h: &Hypotheses, x: &Now) -> Option<&'static str> {
    let (s, v, accel_cmd) = (x.settings, x.speed_mps, x.accel_cmd_mps2);
    let d = &s.tuning.decision;
    let beyond = h.confirmed.is_some_and(|c| beyond_comfort(s, &c, v, accel_cmd) && !can_wait(s, &c, v, accel_cmd));
    // A short TTC alone is no emergency while the ego already brakes about as hard as the
    // threat needs: in a planned stop the TTC (at constant speeds) falls below any threshold as
    // the car comes to rest behind the lead.
    let closing_fast = h.confirmed.is_some_and(|c| {
        let behind_need = c.needed_decel_mps2 > -accel_cmd + d.under_braking_s.get() * s.limits.jerk_mps3;
        c.ttc_s.is_some_and(|ttc| ttc < s.emergency.brake_ttc_s) && behind_need
    });
    // Behind a lead braking hard, only where comfort braking would not keep clear were it
    // braking as estimated (a lead braking at 6 m/s2 40 m ahead of an ego at 15 m/s is
    // stopped behind at 3 m/s2).
    let hard = h.likely.is_some_and(|l| {
        let l = l.or_worse(&h.threat());
        l.needed_decel_mps2 > d.emergency_factor.get() * d.needed_guard_mps2.get() && !can_wait(s, &l, v, accel_cmd)
    });
    [(closing_fast, "closing fast"), (beyond, "beyond comfort"), (hard, "lead braking hard")]
        .into_iter()
        .find_map(|(now, rule)| now.then_some(rule))
}

/// Whether a row of the table holds an emergency on: the threat still close or needing much
/// of the comfort limit, or a lead braking hard with a need above the guard.
fn holds(h: &Hypotheses, s: &AccSettings) -> bool {
    let t = h.threat();
    let d = &s.tuning.decision;
    let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
    let eased = h.likely.is_none() || t.needed_decel_mps2 < d.needed_guard_mps2.get();
    !(eased && ttc > s.emergency.release_ttc_s && t.needed_decel_mps2 < d.release_share.get() * s.limits.decel_mps2)
}

/// The forward-collision warning: TTC below its threshold, or closing within release_ttc_s
/// with more braking needed than comfort allows.
pub(super) fn warns(s: &AccSettings, t: &Threat, v: f64, accel_cmd: f64) -> bool {
    let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
    ttc < s.emergency.warn_ttc_s || beyond_comfort(s, t, v, accel_cmd)
}

/// Closing within release_ttc_s, with more braking needed than comfort allows at this speed
/// and more than comfort braking from here on can give: from the deceleration asked now, at
/// the jerk limit, up to the limit of each speed on the way down (which grows as the speed
/// falls: a stop from 30 m/s 150 m ahead peaks near 4.9 m/s2 at 6 m/s).
fn beyond_comfort(s: &AccSettings, t: &Threat, v: f64, accel_cmd: f64) -> bool {
    let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
    ttc < s.emergency.release_ttc_s && t.needed_decel_mps2 > s.limits.decel_at(v) && !comfort_avoids(s, t, v, accel_cmd)
}

/// Whether an emergency can still wait: comfort braking keeps clear of the threat, or comfort
/// braking for `tuning.decision.wait_s` more and then an emergency at
/// `tuning.decision.planned_emergency_mps2` would still stop the standstill distance behind.
fn can_wait(s: &AccSettings, t: &Threat, v: f64, accel_cmd: f64) -> bool {
    let d = &s.tuning.decision;
    let later = Plan { comfort_s: d.wait_s.get(), then_decel_mps2: d.planned_emergency_mps2.get() };
    comfort_avoids(s, t, v, accel_cmd) || keeps_clear(s, t, v, accel_cmd, later)
}

/// How the ego brakes in a rollout: within the comfort limits for `comfort_s`, then at
/// `then_decel_mps2` (an emergency).
#[derive(Debug, Clone, Copy)]
struct Plan {
    comfort_s: f64,
    then_decel_mps2: f64,
}

/// Whether braking within the comfort limits from now on (the command ramping at the jerk
/// limit from `accel_cmd` to each speed's limit) keeps the threat's room, with the lead going
/// on at its speed and deceleration to a stop.
fn comfort_avoids(s: &AccSettings, t: &Threat, v: f64, accel_cmd: f64) -> bool {
    keeps_clear(s, t, v, accel_cmd, Plan { comfort_s: f64::INFINITY, then_decel_mps2: 0.0 })
}

/// Whether braking as `plan` says keeps the threat's room, with the lead going on at its speed
/// and deceleration to a stop. Simulated in 20 ms steps.
fn keeps_clear(s: &AccSettings, t: &Threat, v: f64, accel_cmd: f64, plan: Plan) -> bool {
    const DT: f64 = 0.02;
    let lim = &s.limits;
    let lead_a = t.lead_accel_mps2.min(0.0);
    let (mut gap, mut v, mut a, mut lead_v) = (t.room_m, v, accel_cmd.min(0.0), t.lead_speed_mps);
    // 60 s of braking stops from any speed the ACC allows.
    for step in 0..3000 {
        if gap < 0.0 {
            return false;
        }
        if v <= 0.0 || (v <= lead_v && (lead_a == 0.0 || lead_v == 0.0)) {
            return true;
        }
        a = if f64::from(step) * DT < plan.comfort_s {
            (a - lim.jerk_mps3 * DT).max(-lim.decel_at(v))
        } else {
            -plan.then_decel_mps2
        };
        v = (v + a * DT).max(0.0);
        lead_v = (lead_v + lead_a * DT).max(0.0);
        gap += (lead_v - v) * DT;
    }
    true
}
