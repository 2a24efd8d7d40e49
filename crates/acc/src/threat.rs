//! The threat a vehicle ahead poses: time to collision and the deceleration that still
//! keeps a margin to it, for a lead holding its speed or braking to a stop.

use super::tuning::ThreatTuning;

/// The least room a need is computed for, m: at or inside the margin the need would divide by
/// zero or turn negative, and this small a room asks the most of the brakes, as it should.
pub(super) const MIN_ROOM_M: f64 = 0.1;
/// Closing slower than this (m/s), a lead has no time to collision: the gap's change is within
/// the estimate's noise, and a TTC from it would be hours or noise.
const MIN_CLOSING_MPS: f64 = 0.1;

/// The threat a lead poses now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Threat {
    pub ttc_s: Option<f64>,
    /// Deceleration (positive) that keeps `tuning.threat.margin_m` to the lead.
    pub needed_decel_mps2: f64,
    /// What it was computed from: the gap less the margin, the lead's speed and
    /// acceleration.
    pub room_m: f64,
    pub lead_speed_mps: f64,
    pub lead_accel_mps2: f64,
}

impl Threat {
    /// The worse of two threats: the shorter TTC and the larger need.
    pub(super) fn or_worse(&self, other: &Threat) -> Threat {
        let ttc_s = match (self.ttc_s, other.ttc_s) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let worse = if other.needed_decel_mps2 > self.needed_decel_mps2 { other } else { self };
        Threat { ttc_s, ..*worse }
    }
}

/// Time to collision and the deceleration that still avoids one, from the gap, the speeds and
/// the lead's acceleration (a lead braking harder than `k.braking_mps2` is assumed to brake to
/// a stop), keeping `k.margin_m`.
pub(crate) fn threat(
    k: &ThreatTuning,
    gap_m: f64,
    ego_speed_mps: f64,
    lead_speed_mps: f64,
    lead_accel_mps2: f64,
) -> Threat {
    let closing = ego_speed_mps - lead_speed_mps;
    let ttc_s = (closing > MIN_CLOSING_MPS).then(|| gap_m.max(0.0) / closing);
    let room = (gap_m - k.margin_m.get()).max(MIN_ROOM_M);
    let lead_decel = (-lead_accel_mps2).max(0.0);
    // Both keep braking until the speeds match: the relative motion decides.
    let matching = if closing > 0.0 { lead_decel + closing * closing / (2.0 * room) } else { 0.0 };
    let lead_speed = lead_speed_mps.max(0.0);
    let of = |needed_decel_mps2: f64| Threat {
        ttc_s,
        needed_decel_mps2,
        room_m: gap_m - k.margin_m.get(),
        lead_speed_mps: lead_speed,
        lead_accel_mps2,
    };
    if lead_accel_mps2 >= -k.braking_mps2.get() {
        return of(matching);
    }
    // A braking lead: does it stop before the speeds would match?
    let lead_stops_first = closing <= 0.0 || {
        let t_match = closing / (matching - lead_decel).max(1e-6);
        lead_speed_mps - lead_decel * t_match <= 0.0
    };
    if lead_stops_first {
        // Then stop behind where it stops (v_L^2 / 2|a_L| on).
        let lead_stop = lead_speed.powi(2) / (2.0 * lead_decel);
        of(ego_speed_mps.powi(2) / (2.0 * (room + lead_stop)))
    } else {
        of(matching)
    }
}
