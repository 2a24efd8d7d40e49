//! The decision between comfort braking and an emergency, and the emergency's deceleration.
//! Comfort braking (the comfort limits, the jerk limit) answers what it can; an emergency
//! starts only where the belief says it cannot, and only for what has been measured in more
//! than one frame: a collision closing fast while the ego brakes less than it needs, a threat
//! that comfort braking from now on would not keep clear of, or
//! a lead braking beyond the comfort limit that comfort braking would not keep clear of were it
//! braking as its estimate says. Those last two wait for the last responsible moment: while
//! comfort braking for a little longer and an emergency after it would still keep clear, the
//! ACC brakes within comfort and looks again (a lead braking hard often stops braking before
//! it stops: then comfort braking was enough, and an emergency would have been for nothing).

use super::settings::AccSettings;
use super::threat::{threat, Threat};

/// Emergency or not, and the lead last found braking beyond the comfort limit.
#[derive(Debug, Clone, Default)]
pub(super) struct Decision {
    pub(super) emergency: bool,
    /// The lead last found braking beyond the comfort limit, while it still is.
    pub(super) hard_lead: Option<u32>,
}

/// What a decision reads this step.
pub(super) struct Situation<'a> {
    pub(super) s: &'a AccSettings,
    /// The threat (on the lead's mildest braking, or what it hides or reveals).
    pub(super) threat: Option<Threat>,
    /// The threat on the lead's likely braking, when it brakes beyond the comfort limit.
    pub(super) hard: Option<Threat>,
    /// The threat of what has been seen in more than one frame (`LeadBelief::confirmed`).
    pub(super) confirmed: Option<Threat>,
    pub(super) v: f64,
    /// The command of the last step (negative: braking).
    pub(super) accel_cmd: f64,
    pub(super) t_s: f64,
}

impl Decision {
    /// Resets: disengaged or stale.
    pub(super) fn clear(&mut self) {
        *self = Decision::default();
    }

    /// Enters an emergency where comfort braking cannot cope (above); leaves it at standstill
    /// or once the threat is comfortably over and the lead no longer brakes hard.
    pub(super) fn update(&mut self, x: &Situation) {
        let Some(t) = x.threat.as_ref() else {
            self.emergency = false;
            return;
        };
        let (s, v) = (x.s, x.v);
        let (e, lim, d) = (&s.emergency, &s.limits, &s.tuning.decision);
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        // An emergency starts only for what has been measured in more than one frame.
        let beyond_comfort =
            x.confirmed.is_some_and(|c| beyond_comfort(s, &c, v, x.accel_cmd) && !can_wait(s, &c, v, x.accel_cmd));
        let hard_lead = x.hard.is_some();
        // The lead brakes hard: an emergency only where comfort braking would not keep clear
        // were it braking as estimated (a lead braking at 6 m/s2 40 m ahead of an ego at
        // 15 m/s is stopped behind at 3 m/s2).
        let hard_and_needed = x.hard.is_some_and(|h| {
            let h = h.or_worse(t);
            h.needed_decel_mps2 > d.emergency_factor.get() * d.needed_guard_mps2.get()
                && !can_wait(s, &h, v, x.accel_cmd)
        });
        // A short TTC alone is no emergency while the ego already brakes about as hard as the
        // threat needs: in a planned stop the TTC (at constant speeds) falls below any
        // threshold as the car comes to rest behind the lead.
        let closing_fast = x.confirmed.is_some_and(|c| {
            let behind_need = c.needed_decel_mps2 > -x.accel_cmd + d.under_braking_s.get() * lim.jerk_mps3;
            c.ttc_s.is_some_and(|ttc| ttc < e.brake_ttc_s) && behind_need
        });
        if !self.emergency && (closing_fast || beyond_comfort || hard_and_needed) {
            tracing::warn!(
                t_s = x.t_s,
                ttc_s = ttc,
                needed_decel_mps2 = t.needed_decel_mps2,
                hard_lead,
                "emergency braking"
            );
            self.emergency = true;
        } else if self.emergency
            && (v < s.tuning.low_level.standstill_mps.get()
                || ((!hard_lead || t.needed_decel_mps2 < d.needed_guard_mps2.get())
                    && ttc > e.release_ttc_s
                    && t.needed_decel_mps2 < d.release_share.get() * lim.decel_mps2))
        {
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

/// The threat with the standstill distance kept as well as the threat's margin (for the
/// brakes' lag and the estimate's error).
fn short_of_standstill(s: &AccSettings, t: &Threat) -> Threat {
    Threat { room_m: t.room_m - s.standstill_m, ..*t }
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
