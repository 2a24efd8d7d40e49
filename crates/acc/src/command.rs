//! The comfort command: Speed or Follow mode within the comfort limits. The lower of the
//! cruise law and the time-gap law, never less braking than the decision table's comfort
//! column asks (`super::decision::comfort_brake_mps2`), moved toward from the last command at
//! the jerk limit; braking whose target has gone, and an ended emergency's braking beyond the
//! comfort limit, are released at the release jerk.

use super::belief::LeadBelief;
use super::settings::AccSettings;
use slipstream_contract::msg::AccMode;

/// A command above this (m/s2) brakes for nothing the release need track.
const RELEASE_FROM_MPS2: f64 = -0.05;

/// The comfort command's memory: the last command and the lead its braking was for.
#[derive(Debug, Clone, Default)]
pub(super) struct Command {
    /// The target acceleration of the last step (jerk-limited outside emergencies).
    pub(super) accel_cmd: f64,
    /// The lead the last command braked for, and its gap then (None: not braking, or braking
    /// for no lead).
    braking_for: Option<(u32, f64)>,
}

/// What the comfort command reads this step.
pub(super) struct Inputs<'a> {
    pub(super) s: &'a AccSettings,
    pub(super) v: f64,
    pub(super) set_speed_mps: f64,
    pub(super) time_gap_s: f64,
    pub(super) lead: Option<LeadBelief>,
    /// The least braking the table's comfort column asks (m/s2; None: the law alone).
    pub(super) brake_at_least_mps2: Option<f64>,
    pub(super) dt: f64,
}

impl Command {
    /// Remembers the command of this step, and the lead its braking is for: the lead it
    /// follows, kept while that braking is released after the lead has gone; none once the
    /// command no longer brakes, or outside Speed and Follow.
    pub(super) fn set(&mut self, accel: f64, mode: AccMode, lead: Option<&LeadBelief>) {
        self.braking_for = match mode {
            _ if accel >= RELEASE_FROM_MPS2 => None,
            AccMode::Follow => lead.map(|l| (l.id, l.gap_m)).or(self.braking_for),
            AccMode::Speed => self.braking_for,
            _ => None,
        };
        self.accel_cmd = accel;
    }

    /// The comfort target and its mode, jerk-limited from the last command: at the comfort
    /// jerk, except that braking for a lead that has gone (no lead now, or a new one beyond
    /// where it was: it left the lane, or was never there) is released at `release_jerk_mps3`
    /// toward the new target, up to no braking at all. A new lead where the old one was is the
    /// same vehicle tracked anew, not a target gone.
    pub(super) fn comfort(&self, x: &Inputs) -> (AccMode, f64) {
        let (g, lim) = (&x.s.gains, &x.s.limits);
        let v = x.v;
        let decel = lim.decel_at(v);
        let cruise = (g.cruise_per_s * (x.set_speed_mps - v)).clamp(-decel, lim.accel_mps2);
        let follow = x.lead.map(|l| self.follow(x, &l));
        let (mode, target) = match follow {
            Some(f) if f < cruise => (AccMode::Follow, f),
            _ => (AccMode::Speed, cruise),
        };
        let target = target.clamp(-decel, lim.accel_mps2);
        let step = lim.jerk_mps3 * x.dt;
        let beyond_m = x.s.tuning.select.beyond_lead_m.get();
        let gone =
            self.braking_for.is_some_and(|(id, gap)| x.lead.is_none_or(|l| l.id != id && l.gap_m > gap + beyond_m));
        let release = x.s.tuning.command.release_jerk_mps3.get() * x.dt;
        let up = if gone {
            (self.accel_cmd + release).min(target.min(0.0)).max(self.accel_cmd + step)
        } else if self.accel_cmd < -decel {
            // Braking beyond the comfort limit is an emergency's, which has ended: released at
            // the release jerk down to the limit, then eased at the comfort jerk.
            (self.accel_cmd + release).min(-decel).max(self.accel_cmd + step)
        } else {
            self.accel_cmd + step
        };
        (mode, target.clamp(self.accel_cmd - step, up))
    }

    /// The time-gap law for `l`: a = gap gain x (gap - desired) + speed gain x (lead speed -
    /// speed), never less braking than the decision asks; at standstill, staying until the
    /// lead has moved off.
    fn follow(&self, x: &Inputs, l: &LeadBelief) -> f64 {
        let (s, v) = (x.s, x.v);
        let desired_gap = s.standstill_m + x.time_gap_s * v;
        let law = s.gains.gap_per_s2 * (l.gap_m - desired_gap) + s.gains.speed_per_s * (l.speed_mps - v);
        let mut a = x.brake_at_least_mps2.map_or(law, |b| law.min(-b));
        let c = &s.tuning.command;
        let driven_off = l.gap_m > s.standstill_m + c.drive_off_gap_m.get() && l.speed_mps > c.drive_off_lead_mps.get();
        if v < s.tuning.low_level.standstill_mps.get() && !driven_off {
            a = a.min(-c.standstill_hold_mps2.get());
        }
        a
    }
}
