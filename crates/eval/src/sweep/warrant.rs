//! What a generated scenario's own physics warrants: the constant deceleration that keeps the
//! ego behind a vehicle in its lane, from the moment it can be seen and after a reaction, and
//! from that the most braking the scenario declares (`expect.braking`). The judge then holds
//! the ACC to the scenario's physics, not to the ACC's own opinion of it.

use crate::metrics::aims;
use slipstream_acc::settings::comfort_decel_at;
use slipstream_contract::msg::ObjectClass;
use slipstream_sim::scenario::Warranted;

/// From the target's first sight to the ACC braking at the rate it chose: the detector's
/// confirmation, the lead estimate settling, the jerk-limited ramp (2.2 m/s3 to 3 m/s2 is
/// 1.4 s; half of it counts as dead time). Taken generously, so that what is declared
/// `comfort` leaves the ACC room.
pub(crate) const REACTION_S: f64 = 0.8;
/// The gap kept when stopped behind a target in these calculations (below the ACC's standstill
/// distance of 5 m: the judge's own margin).
pub(crate) const STOP_MARGIN_M: f64 = 3.0;
/// A share of the comfort limit: needs up to this are declared `comfort`; beyond, an
/// emergency may be needed (the borderline is given to the ACC).
pub(crate) const COMFORT_SHARE: f64 = 0.8;
/// The most deceleration a scenario may need and still be generated: two thirds of the
/// vehicle's 9 m/s2 brakes. Beyond it a collision is the physics', not the ACC's.
pub(crate) const AVOIDABLE_MPS2: f64 = 6.0;

/// Where the camera perception is taken to see a vehicle in the ego's lane, by class: below
/// what the detector's unit tests find through the narrow camera (cars to 150 m, trucks to
/// 200 m; docs/perception.md), a narrow motorcycle nearer.
pub(crate) fn seen_from_m(class: ObjectClass) -> f64 {
    match class {
        ObjectClass::Truck => 160.0,
        ObjectClass::Motorcycle => 90.0,
        _ => 130.0,
    }
}

/// A vehicle in the ego's lane when it is first seen: its gap (bumper to bumper), speed, and
/// deceleration down to `floor_mps` (0: to a stop).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Target {
    pub gap_m: f64,
    pub speed_mps: f64,
    pub decel_mps2: f64,
    pub floor_mps: f64,
}

/// The constant deceleration the ego at `ego_mps` needs, starting after [`REACTION_S`], to
/// stay [`STOP_MARGIN_M`] behind `target` (0 when it never closes in). Found by bisection over
/// a kinematic rollout, so braking targets, slow targets and standing ones are one case.
pub(crate) fn needed_decel(ego_mps: f64, target: Target) -> f64 {
    if !keeps_clear(ego_mps, target, 30.0) {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (0.0, 30.0);
    if keeps_clear(ego_mps, target, 0.0) {
        return 0.0;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if keeps_clear(ego_mps, target, mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Whether braking at `decel` after the reaction keeps the margin.
fn keeps_clear(ego_mps: f64, t: Target, decel: f64) -> bool {
    rollout(ego_mps, t, |time, _| if time >= REACTION_S { decel } else { 0.0 })
}

/// Whether the ego at `ego_mps`, braking at `decel(time, speed)`, keeps the margin behind `t`:
/// the two rolled forward at 10 ms until the ego is no faster than the target and the target
/// no longer slows.
fn rollout(ego_mps: f64, t: Target, decel: impl Fn(f64, f64) -> f64) -> bool {
    const DT: f64 = 0.01;
    let (mut gap, mut v, mut u, mut time) = (t.gap_m, ego_mps, t.speed_mps, 0.0);
    for _ in 0..60_000 {
        let target_slowing = u > t.floor_mps && t.decel_mps2 > 0.0;
        if v <= u && !target_slowing {
            break;
        }
        if gap < STOP_MARGIN_M {
            return false;
        }
        v = (v - decel(time, v) * DT).max(0.0);
        if target_slowing {
            u = (u - t.decel_mps2 * DT).max(t.floor_mps);
        }
        gap += (u - v) * DT;
        time += DT;
    }
    gap >= STOP_MARGIN_M
}

/// The most braking a braking lead warrants, judged on what can be known while it brakes.
/// Where it stops braking is not known until it has: until then a lead braking at `decel` is
/// one braking on to a stop. So an emergency is warranted when a driver who brakes within the
/// comfort limit (after [`REACTION_S`]) until the lead's braking ends, and only then at
/// [`AVOIDABLE_MPS2`], would not keep clear of that lead had it braked on to a stop: the
/// decision to brake harder had to come while the lead was still braking. Otherwise (and for
/// braking that ends within the reaction, known to have ended before anyone answers it), what
/// its whole braking needs ([`needed_decel`]) decides.
pub(crate) fn warranted_for_braking_lead(ego_mps: f64, lead: Target) -> Warranted {
    let hindsight = warranted_for(needed_decel(ego_mps, lead), ego_mps);
    if lead.decel_mps2 <= 0.0 || lead.speed_mps <= lead.floor_mps {
        return hindsight;
    }
    let braking_s = (lead.speed_mps - lead.floor_mps) / lead.decel_mps2;
    let to_stop = Target { floor_mps: 0.0, ..lead };
    if braking_s <= REACTION_S || waiting_keeps_clear(ego_mps, to_stop, braking_s) {
        hindsight
    } else {
        most(hindsight, Warranted::Emergency)
    }
}

/// Whether the ego, braking at the comfort limit of its speed from [`REACTION_S`] until
/// `wait_s` and at [`AVOIDABLE_MPS2`] after, keeps the margin behind `t`.
fn waiting_keeps_clear(ego_mps: f64, t: Target, wait_s: f64) -> bool {
    rollout(ego_mps, t, |time, v| {
        if time < REACTION_S {
            0.0
        } else if time < wait_s {
            comfort_decel_at(v, aims::MAX_DECEL_MPS2, aims::MAX_DECEL_LOW_SPEED_MPS2)
        } else {
            AVOIDABLE_MPS2
        }
    })
}

/// The most braking a need declares: within [`COMFORT_SHARE`] of the comfort limit at the
/// ego's speed, comfort; beyond, an emergency may be needed.
pub(crate) fn warranted_for(need_mps2: f64, ego_mps: f64) -> Warranted {
    let limit = comfort_decel_at(ego_mps, aims::MAX_DECEL_MPS2, aims::MAX_DECEL_LOW_SPEED_MPS2);
    if need_mps2 <= COMFORT_SHARE * limit {
        Warranted::Comfort
    } else {
        Warranted::Emergency
    }
}

/// The more of two declarations.
pub(crate) fn most(a: Warranted, b: Warranted) -> Warranted {
    let rank = |w: Warranted| match w {
        Warranted::None => 0,
        Warranted::Comfort => 1,
        Warranted::Emergency => 2,
    };
    if rank(a) >= rank(b) {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn standing(gap_m: f64) -> Target {
        Target { gap_m, speed_mps: 0.0, decel_mps2: 0.0, floor_mps: 0.0 }
    }

    #[test]
    fn a_standing_target_needs_the_braking_of_the_textbook() {
        // 25 m/s, 150 m: 20 m of reaction, then 127 m to stop in: 2.46 m/s2.
        let need = needed_decel(25.0, standing(150.0));
        let room = 150.0 - STOP_MARGIN_M - 25.0 * REACTION_S;
        assert!((need - 25.0 * 25.0 / (2.0 * room)).abs() < 0.05, "{need}");
        assert_eq!(warranted_for(need, 25.0), Warranted::Comfort);
        // The same from 80 m: 57 m to stop in, 5.5 m/s2, an emergency.
        let near = needed_decel(25.0, standing(80.0));
        assert!((near - 25.0 * 25.0 / (2.0 * 57.0)).abs() < 0.05, "{near}");
        assert_eq!(warranted_for(near, 25.0), Warranted::Emergency);
    }

    #[test]
    fn a_target_that_is_faster_or_as_fast_needs_nothing() {
        let moving = Target { gap_m: 20.0, speed_mps: 25.0, decel_mps2: 0.0, floor_mps: 25.0 };
        assert_eq!(needed_decel(25.0, moving), 0.0);
        assert_eq!(needed_decel(20.0, moving), 0.0);
    }

    #[test]
    fn a_braking_lead_needs_more_the_closer_and_harder_it_brakes() {
        // Euro NCAP's CCRb at 50 km/h: 6 m/s2 at 12 m needs more than 2 m/s2 at 40 m.
        let ccrb =
            |gap_m, decel_mps2| needed_decel(13.9, Target { gap_m, speed_mps: 13.9, decel_mps2, floor_mps: 0.0 });
        let (hard_near, soft_far) = (ccrb(12.0, 6.0), ccrb(40.0, 2.0));
        assert!(hard_near > 6.0, "{hard_near}");
        assert!(soft_far < 1.5, "{soft_far}");
        // Braking to a lower speed needs less than braking to a stop.
        let to_half = needed_decel(25.0, Target { gap_m: 30.0, speed_mps: 25.0, decel_mps2: 4.0, floor_mps: 12.5 });
        let to_stop = needed_decel(25.0, Target { gap_m: 30.0, speed_mps: 25.0, decel_mps2: 4.0, floor_mps: 0.0 });
        assert!(to_half < to_stop, "{to_half} {to_stop}");
    }

    #[test]
    fn a_lead_braking_hard_warrants_an_emergency_when_its_end_comes_too_late_to_wait_for() {
        // 8 m/s2 at a 1.1 s gap from 31.5 m/s, stopping its braking at 19.2 m/s 1.5 s later:
        // in hindsight comfort braking keeps clear, but had it braked on to a stop, a driver
        // waiting for the end of its braking would have hit it.
        let short = Target { gap_m: 39.7, speed_mps: 31.5, decel_mps2: 8.0, floor_mps: 19.2 };
        assert_eq!(warranted_for(needed_decel(31.5, short), 31.5), Warranted::Comfort);
        assert_eq!(warranted_for_braking_lead(31.5, short), Warranted::Emergency);
        // The same lead far ahead leaves time to wait for the end of its braking.
        let far = Target { gap_m: 80.0, ..short };
        assert_eq!(warranted_for_braking_lead(31.5, far), Warranted::Comfort);
        // A brief dab of hard braking ends before anyone could answer it.
        let dab = Target { floor_mps: 29.5, ..short };
        assert_eq!(warranted_for_braking_lead(31.5, dab), Warranted::Comfort);
        // Braking within comfort warrants no emergency, whatever its length.
        let gentle = Target { gap_m: 39.7, speed_mps: 31.5, decel_mps2: 2.0, floor_mps: 0.0 };
        assert_eq!(warranted_for_braking_lead(31.5, gentle), Warranted::Comfort);
    }

    #[test]
    fn an_unavoidable_target_needs_more_than_any_brakes() {
        assert!(needed_decel(36.0, standing(10.0)) > AVOIDABLE_MPS2);
        assert_eq!(most(Warranted::Comfort, Warranted::None), Warranted::Comfort);
        assert_eq!(most(Warranted::Comfort, Warranted::Emergency), Warranted::Emergency);
    }
}
