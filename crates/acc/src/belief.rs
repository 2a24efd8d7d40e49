//! The lead belief: what the lead plausibly does, in one place. The lead estimate (the Kalman
//! filter) gives a speed and an acceleration with their uncertainty; its brake lamps, its age
//! and how noisy its speed reads say how far to trust them. From these the belief gives the
//! ranges the rest of the ACC reads, instead of each part keeping a rule of its own:
//!
//! - the lead's acceleration: **likely** (the estimate), **mildest** (the least braking it
//!   plausibly does: the estimate less one standard deviation toward zero, unless held lamps
//!   vouch for it) and, for the moment after its lamps come on, **hardest** (braking at the
//!   comfort limit at least, before its speed can say);
//! - its speed: the estimate, and while a new lead's speed is still being measured the
//!   **slowest** it plausibly is;
//! - whether it **brakes beyond the comfort limit** (its mildest deceleration past the limit by
//!   the perception's margin, held until it brakes less than the limit).
//!
//! From these it yields the hypotheses ([`Hypotheses`]: mildest, revealed, confirmed, likely,
//! hardest), each as the threat it would pose, which the decision's one table maps to comfort
//! braking or an emergency (`super::decision`).

use super::lead_filter::LeadFilter;
use super::settings::AccSettings;
use super::threat::{threat, Threat};
use super::tuning::ThreatTuning;

/// What the lead hides or reveals in the lane (the nearest vehicle past it, or entering before
/// it: `super::select`), as a threat: as seen, and once seen over the confirmation time.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Around {
    pub(super) revealed: Option<Threat>,
    pub(super) revealed_confirmed: Option<Threat>,
}

/// The lead's hypotheses this step, each as the threat it would pose.
#[derive(Debug, Clone, Copy)]
pub(super) struct Hypotheses {
    /// The lead braking the least it plausibly does.
    pub(super) mildest: Threat,
    /// The vehicle it hides or reveals, holding its measured speed.
    pub(super) revealed: Option<Threat>,
    /// The mildest or the revealed, whichever is worse, once each has been measured over
    /// `tuning.decision.confirm_s` (in more than one frame; a vehicle in the lane for one frame
    /// may be a lane changer's measurement); None before.
    pub(super) confirmed: Option<Threat>,
    /// The lead braking as estimated, while it brakes beyond the comfort limit.
    pub(super) likely: Option<Threat>,
    pub(super) hardest: Hardest,
}

impl Hypotheses {
    /// The threat: the mildest or the revealed, whichever is worse.
    pub(super) fn threat(&self) -> Threat {
        self.revealed.map_or(self.mildest, |r| self.mildest.or_worse(&r))
    }
}

/// The worst the lead plausibly does while it is not yet measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Hardest {
    /// Measured: nothing worse than the mildest is plausible.
    Measured,
    /// A new lead at its slowest speed, or a lead whose lamps just came on braking at the
    /// comfort limit at least.
    Is(Threat),
    /// A new lead far ahead whose wait to be measured costs little comfort: not planned for
    /// yet, only what it hides or reveals.
    NotYet,
}

/// The lead as believed now.
#[derive(Debug, Clone, Copy)]
pub(super) struct LeadBelief {
    pub(super) id: u32,
    pub(super) gap_m: f64,
    pub(super) speed_mps: f64,
    /// The estimate of its acceleration, and that estimate's standard deviation.
    pub(super) accel_mps2: f64,
    accel_sigma_mps2: f64,
    speed_sigma_mps: f64,
    pub(super) brake_lights: bool,
    /// Its lamps are held on, on a lead whose speed reads finely (`LeadFilter::lamps_vouch`).
    lamps_vouch: bool,
    /// How long ago they came on (a settled lead's, while on).
    lit_for_s: Option<f64>,
    pub(super) settled: bool,
    /// How long it has been the lead, and from its first to its last measured frame.
    followed_s: f64,
    measured_for_s: f64,
}

impl LeadBelief {
    pub(super) fn of(f: &LeadFilter) -> Self {
        LeadBelief {
            id: f.id,
            gap_m: f.x[0],
            speed_mps: f.x[1].max(0.0),
            accel_mps2: f.x[2],
            accel_sigma_mps2: f.p[(2, 2)].max(0.0).sqrt(),
            speed_sigma_mps: f.p[(1, 1)].max(0.0).sqrt(),
            brake_lights: f.brake_lights,
            lamps_vouch: f.lamps_vouch(),
            lit_for_s: f.lit_for_s(),
            settled: f.settled(),
            followed_s: f.t_s - f.since_s,
            measured_for_s: f.seen_s - f.since_s,
        }
    }

    /// The least braking the lead plausibly does. Far away a camera's ranges leave the
    /// estimate wandering within its uncertainty (about a sigma's worth for a lead at constant
    /// speed 150 m ahead), so the estimate as it stands would brake for a lead that does not.
    /// Held lamps on a lead whose speed reads finely vouch for the estimate; a flash of them
    /// does not (a driver dabbing the pedal to hold a speed), nor lamps on a lead whose speed
    /// reads coarsely (its estimate then overshoots its real braking several times).
    pub(super) fn mildest_accel(&self) -> f64 {
        if self.lamps_vouch {
            return self.accel_mps2;
        }
        self.accel_mps2.signum() * (self.accel_mps2.abs() - self.accel_sigma_mps2).max(0.0)
    }

    /// The threat judged on the mildest braking.
    pub(super) fn threat(&self, k: &ThreatTuning, v: f64) -> Threat {
        threat(k, self.gap_m, v, self.speed_mps, self.mildest_accel())
    }

    /// The threat judged on the likely braking (the estimate itself).
    pub(super) fn likely_threat(&self, k: &ThreatTuning, v: f64) -> Threat {
        threat(k, self.gap_m, v, self.speed_mps, self.accel_mps2)
    }

    /// Whether the lead brakes beyond the comfort limit: its mildest deceleration past the
    /// limit by `margin`, or, when it was found so before (`was_hard`), its estimate still
    /// within `hard_braking_release_mps2` of the limit (without the hold, an estimate wandering
    /// about the threshold while the deceleration builds made an emergency flicker). Never a
    /// lead that is not settled or is nearly standing.
    pub(super) fn brakes_hard(&self, s: &AccSettings, margin: f64, was_hard: bool) -> bool {
        let b = &s.tuning.belief;
        let limit = s.limits.decel_mps2;
        self.settled
            && self.speed_mps > b.hard_braking_min_speed_mps.get()
            && (self.mildest_accel() < -limit - margin
                || (was_hard && self.accel_mps2 < -limit + b.hard_braking_release_mps2.get()))
    }

    /// Whether the lead has been measured over `confirm_s` (in more than one frame; a lead
    /// predicted through missed frames is not measured): a vehicle in the lane for one frame
    /// may be a lane changer's measurement, not a lead.
    pub(super) fn confirmed(&self, confirm_s: f64) -> bool {
        self.measured_for_s >= confirm_s - 1e-9
    }

    /// Whether the lead is seen braking harder than `decel` with its lamps lit.
    pub(super) fn seen_braking(&self, decel: f64) -> bool {
        self.brake_lights && self.mildest_accel() <= -decel
    }

    /// The hypotheses this step (`super::decision` maps each one's need to the decision):
    /// the mildest, what the lead hides or reveals (`around`), both as confirmed, the likely
    /// braking while the lead brakes beyond the comfort limit (`hard`: the perception's
    /// margin, and whether it was found so before), and the hardest.
    pub(super) fn hypotheses(
        &self,
        s: &AccSettings,
        v: f64,
        time_gap_s: f64,
        around: Around,
        hard: (f64, bool),
    ) -> Hypotheses {
        let k = &s.tuning.threat;
        let mildest = self.threat(k, v);
        let confirmed = self
            .confirmed(s.tuning.decision.confirm_s.get())
            .then(|| around.revealed_confirmed.map_or(mildest, |r| mildest.or_worse(&r)));
        let likely = self.brakes_hard(s, hard.0, hard.1).then(|| self.likely_threat(k, v));
        Hypotheses { mildest, revealed: around.revealed, confirmed, likely, hardest: self.hardest(s, v, time_gap_s) }
    }

    /// The worst the lead plausibly does before it is measured.
    ///
    /// - A new lead's speed is still being measured (far ahead, a camera needs a few tenths of
    ///   a second): its slowest, so a standing car seen at the edge of range is braked for from
    ///   the first frames. Beyond twice the time gap only where waiting would cost comfort: far
    ///   away a "lead" may be no vehicle (in a bend, two cars standing either side 200 m ahead
    ///   merged into one in the ego's lane for half a second); there it is not yet planned for.
    /// - For a moment after its lamps come on, the pedal is pressed but its speed cannot yet
    ///   say how hard: braking at the comfort limit, where that would need much of the comfort
    ///   braking (slow and far back, a late answer costs nothing, and braking for every touch
    ///   of the pedal would cost the time gap).
    fn hardest(&self, s: &AccSettings, v: f64, time_gap_s: f64) -> Hardest {
        let b = &s.tuning.belief;
        let decel = s.limits.decel_at(v);
        if !self.settled {
            let slowest = (self.speed_mps - b.unmeasured_sigmas.get() * self.speed_sigma_mps).max(0.0);
            let slower = |gap_m: f64| threat(&s.tuning.threat, gap_m, v, slowest, self.mildest_accel());
            let far = self.gap_m > s.standstill_m + s.tuning.command.far_time_gaps.get() * time_gap_s * v;
            let wait_s = (s.tuning.filter.settle_s.get() - self.followed_s).max(0.0);
            let waited = slower(self.gap_m - (v - slowest).max(0.0) * wait_s);
            if far && waited.needed_decel_mps2 <= b.unsettled_wait_share.get() * decel {
                return Hardest::NotYet;
            }
            return Hardest::Is(slower(self.gap_m));
        }
        if self.lit_for_s.is_some_and(|t| t < b.lit_anticipation_s.get()) {
            let hardest = self.mildest_accel().min(-s.limits.decel_mps2);
            let hard = threat(&s.tuning.threat, self.gap_m, v, self.speed_mps, hardest);
            if hard.needed_decel_mps2 >= b.lit_need_share.get() * decel {
                return Hardest::Is(hard);
            }
        }
        Hardest::Measured
    }
}
