//! The ACC's decisions, free of any I/O: lead selection, the spacing law, collision warning and
//! emergency braking, the stale-data fallback and the low-level loop from target acceleration
//! to throttle and brake. The node (`super::node`) feeds it; tests drive it directly. Its
//! parts each have a file: the ego's motion ([`super::ego`]), the objects it is fed
//! ([`super::objects`]), the lane ahead ([`super::lane`]), the lead estimate
//! ([`super::lead_filter`]) and the threat ([`super::threat`]).
//!
//! Units: seconds of simulated time, metres, m/s, m/s2. The ego's body frame: x forward from the
//! rear axle, y left.

use std::collections::HashMap;

use super::ego::EgoNow;
use super::lane::LaneAhead;
use super::lead_filter::{LeadFilter, Noise, SETTLE_S};
use super::objects::{Object, PerceptionFrame};
use super::settings::{AccSettings, PerceptionSource, TIME_GAP_RANGE_S};
use super::threat::{threat, Threat, THREAT_MARGIN_M};
use crate::msg::{AccCommand, AccMode, AccStatus, AccWarning, LeadInfo, RoadSpec};
use crate::road::Road;
use crate::vehicle::{actuate_acceleration, VehicleParams};

/// What one control step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    pub throttle: f32,
    pub brake: f32,
    pub status: AccStatus,
}

/// What the controller remembers of one track (for its lateral speed).
#[derive(Debug, Clone, Copy)]
struct Track {
    stamp_s: f64,
    /// Its offset from the ego's lane centre (or predicted path, without a map).
    lateral_m: f64,
    lateral_rate_mps: f64,
    seen: u32,
}

/// The lane width the settings' in-lane limits are for.
const SETTINGS_LANE_WIDTH_M: f64 = 3.5;
/// Filter constant for the per-track lateral speed, per perception frame.
const RATE_FILTER: f64 = 0.3;
/// The fastest a vehicle moves sideways (a swerve; a lane change takes ~1 m/s). A larger
/// step between two frames is the measurement jumping (a vehicle being passed, cut by the
/// image's side, is measured on what of it is still in view), not the vehicle: it counts
/// as this much.
const MAX_LATERAL_RATE_MPS: f64 = 3.0;
/// The collision-avoidance guard on the follow law takes over above this needed deceleration.
const NEEDED_GUARD_MPS2: f64 = 1.0;
/// A threat farther than this many time gaps, not closing fast (matching its speed needs less
/// than FAR_CLOSING_MPS2), is answered at most at FAR_DECEL_MPS2 (`Controller::far_cap_mps2`).
const FAR_TIME_GAPS: f64 = 2.0;
const FAR_CLOSING_MPS2: f64 = 0.5;
const FAR_DECEL_MPS2: f64 = 0.8;
/// Unless it is seen braking harder than this with its brake lights on: no touch of the
/// brakes, and 120 m ahead at 30 m/s one braking at 5 m/s2 was answered 1.35 s after it passed
/// the comfort limit. Its estimate alone is not enough that far: a new lead's speed still
/// settling reads as braking (a car 170 m ahead at 22 m/s, -3.8 m/s2 for a second against a
/// sigma of 1.4, drew 1.3 s of phantom braking at up to 1.9 m/s2).
const FAR_BRAKING_MPS2: f64 = 2.5;
/// For this long after a lead's brake lights come on, before its speed can say how hard it
/// brakes, comfort braking plans for it braking at the comfort limit (`Controller::step`).
pub(super) const LIT_ANTICIPATION_S: f64 = 0.5;
/// ...where a lead braking at the comfort limit would need at least this share of it.
const LIT_NEED_SHARE: f64 = 0.4;
/// While a new lead's speed is still being measured, comfort braking plans for it being this
/// many of its standard deviations slower.
const UNMEASURED_SIGMAS: f64 = 2.0;
/// ...unless, were it that slow, the stop behind it after waiting until it is settled would need
/// at most this share of the comfort limit: then it is braked for once measured.
const UNSETTLED_WAIT_SHARE: f64 = 0.7;
/// How long a lead missing from perception's frames is kept, predicted.
const LEAD_COAST_S: f64 = 0.3;
/// ...and a settled lead slower than STANDING_LEAD_MPS for this long.
const STANDING_COAST_S: f64 = 2.0;
const STANDING_LEAD_MPS: f64 = 1.0;
/// A vehicle counts as beyond the lead from this far past it (not the lead seen twice).
const BEYOND_LEAD_M: f64 = 3.0;
/// With ground truth a lead counts as braking beyond comfort when its estimated deceleration
/// exceeds the comfort limit by this much (the camera's margin is a setting): the estimate
/// converges on the true deceleration from below, so this only keeps a lead braking at the
/// limit itself from flickering in and out.
const GROUND_TRUTH_HARD_BRAKING_MARGIN_MPS2: f64 = 0.1;
/// A lead slower than this is stopping or stopped, not braking hard from speed.
const HARD_BRAKING_MIN_SPEED_MPS: f64 = 2.0;
/// A lead found braking hard counts so until it brakes less than the comfort limit by this.
const HARD_BRAKING_RELEASE_MPS2: f64 = 0.5;
/// An emergency brakes at this many times what the threat needs (below full_brake_ttc_s); for a
/// lead braking hard it starts once that is more than NEEDED_GUARD_MPS2 this many times over.
const HARD_LEAD_EMERGENCY_FACTOR: f64 = 1.5;
/// A short TTC starts an emergency only when the ego brakes less than the threat needs by more
/// than the jerk limit adds in this long.
const UNDER_BRAKING_S: f64 = 0.25;
/// Below this speed the ego counts as standing.
const STANDSTILL_MPS: f64 = 0.2;
/// Brake held at standstill.
const HOLD_BRAKE: f32 = 0.3;
/// Integrator of the low-level loop: gain (1/s) and bound (m/s2).
const LOW_LEVEL_KI: f64 = 0.5;
const LOW_LEVEL_I_MAX: f64 = 0.7;

/// The lead as estimated now.
#[derive(Debug, Clone, Copy)]
struct LeadNow {
    id: u32,
    gap_m: f64,
    speed_mps: f64,
    accel_mps2: f64,
    /// The speed estimate's standard deviation.
    speed_sigma_mps: f64,
    /// The acceleration estimate's standard deviation.
    accel_sigma_mps2: f64,
    /// Its brake lights are on.
    brake_lights: bool,
    /// ...and vouch for its estimated acceleration: held on in every frame for LIT_HELD_S at
    /// least (the pedal held, not dabbed), on a lead whose speed reads within
    /// LAMPS_VOUCH_NOISE_MPS.
    lamps_vouch: bool,
    /// How long ago they came on (a settled lead's, while on).
    lit_for_s: Option<f64>,
    settled: bool,
    /// How long it has been the lead.
    followed_s: f64,
    /// How noisy its speed reads (`LeadFilter::speed_noise_var`).
    speed_noise_mps: f64,
}

impl LeadNow {
    /// The acceleration the threat is judged on. Where the lead's brake lights vouch for it
    /// (`lamps_vouch`), the estimate as it is (the lights say it brakes); otherwise the
    /// estimate less one standard deviation toward zero. Far away a camera's ranges leave the
    /// estimate wandering within its uncertainty (-1.1 m/s2 against a sigma of 1.3 for a van 165 m ahead at constant
    /// speed), and taken as it was that drew comfort braking for a lead that did not brake;
    /// noise alone may also look like a manoeuvre to the drift test. The hard-braking rule
    /// reads the estimate itself. A flash of the lamps vouches for nothing: 170 m ahead, a
    /// car whose driver dabbed the pedal to hold a speed after braking flashed them for a
    /// frame at a time while its speed, read to +-4 m/s, swung the estimate between +5 and
    /// -4.7 m/s2, and the estimate as it was at a flash drew an emergency with a TTC of 17 s.
    /// Nor do lamps held on where the speed reads too coarsely: 143 m ahead, a car braking to
    /// stop behind one standing was estimated at -6.6 m/s2 half a second after its pedal, which
    /// drew a 5 s emergency at 1.2-1.6 m/s2 where stopping behind it needed 0.8.
    fn threat_accel(&self) -> f64 {
        if self.lamps_vouch {
            return self.accel_mps2;
        }
        self.accel_mps2.signum() * (self.accel_mps2.abs() - self.accel_sigma_mps2).max(0.0)
    }
}

pub struct Controller {
    s: AccSettings,
    /// The road's map (sim/road), when one was received, and the ego's last place along it.
    road: Option<Road>,
    road_s_m: Option<f64>,
    params: VehicleParams,
    enabled: bool,
    set_speed_mps: f64,
    time_gap_s: f64,
    tracks: HashMap<u32, Track>,
    lead: Option<LeadFilter>,
    noise: Noise,
    last_t_s: Option<f64>,
    /// The target acceleration of the last step (jerk-limited outside emergencies).
    accel_cmd: f64,
    integral: f64,
    /// The throttle of the last step: while stale, never more than this.
    last_throttle: f64,
    emergency: bool,
    /// The lead last found braking beyond the comfort limit, while it still is.
    hard_lead: Option<u32>,
    /// The nearest vehicle that is in the ego's lane by the entry test while the lead stays
    /// the lead only by the stay-in-lane hysteresis (a lead moving out), else the nearest in
    /// the lane beyond the lead: it counts for the threat at once, not once the lead has left.
    next_in_lane: Option<Revealed>,
}

/// A vehicle in the lane beyond the lead, or one a leaving lead reveals, as last measured.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Revealed {
    stamp_s: f64,
    gap_m: f64,
    relative_speed_mps: f64,
}

impl Controller {
    pub fn new(settings: AccSettings) -> Self {
        let noise = match settings.perception {
            PerceptionSource::Camera => Noise {
                gap_base_m: settings.estimator.gap_sigma_m,
                gap_per_m2: settings.estimator.gap_sigma_per_m2,
                speed_base_mps: settings.estimator.speed_sigma_mps,
                speed_per_m2: settings.estimator.speed_sigma_per_m2,
                speed_steady_mps: settings.estimator.steady_speed_sigma_mps,
                jerk_sigma_mps3: settings.estimator.lead_jerk_sigma_mps3,
                hard_braking_margin_mps2: settings.estimator.hard_braking_margin_mps2,
            },
            // Exact measurements: the filter follows them.
            PerceptionSource::GroundTruth => Noise {
                gap_base_m: 0.05,
                gap_per_m2: 0.0,
                speed_base_mps: 0.05,
                speed_per_m2: 0.0,
                speed_steady_mps: 0.05,
                jerk_sigma_mps3: settings.estimator.lead_jerk_sigma_mps3,
                hard_braking_margin_mps2: GROUND_TRUTH_HARD_BRAKING_MARGIN_MPS2,
            },
        };
        Controller {
            params: settings.vehicle.params(),
            enabled: settings.enabled,
            set_speed_mps: settings.set_speed_mps,
            time_gap_s: settings.time_gap_s,
            s: settings,
            road: None,
            road_s_m: None,
            tracks: HashMap::new(),
            lead: None,
            noise,
            last_t_s: None,
            accel_cmd: 0.0,
            integral: 0.0,
            last_throttle: 0.0,
            emergency: false,
            hard_lead: None,
            next_in_lane: None,
        }
    }

    pub fn settings(&self) -> &AccSettings {
        &self.s
    }

    pub fn set_speed_mps(&self) -> f64 {
        self.set_speed_mps
    }

    pub fn time_gap_s(&self) -> f64 {
        self.time_gap_s
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// Applies acc/command; returns what was refused (a time gap outside the allowed range is
    /// clamped into it).
    pub fn command(&mut self, cmd: &AccCommand) -> Option<String> {
        let mut note = None;
        if let Some(e) = cmd.enable {
            if e != self.enabled {
                tracing::info!(enabled = e, "acc/command: {}", if e { "engaged" } else { "disengaged" });
            }
            self.enabled = e;
            if e {
                self.emergency = false;
            }
        }
        if let Some(v) = cmd.set_speed_mps {
            self.set_speed_mps = v.clamp(0.0, 70.0);
            tracing::info!(set_speed_mps = self.set_speed_mps, "acc/command: set speed");
        }
        if let Some(h) = cmd.time_gap_s {
            let clamped = h.clamp(*TIME_GAP_RANGE_S.start(), *TIME_GAP_RANGE_S.end());
            if clamped != h {
                note = Some(format!("time gap {h} s is outside 0.8..3.0 s; using {clamped} s"));
            }
            self.time_gap_s = clamped;
            tracing::info!(time_gap_s = self.time_gap_s, "acc/command: time gap");
        }
        note
    }

    /// Takes the road's map (sim/road): from now on the lane ahead comes from it wherever the
    /// ego's pose is known and on the road.
    pub fn set_road(&mut self, spec: &RoadSpec) {
        if self.road.as_ref().is_some_and(|r| r.spec() == spec) {
            return;
        }
        tracing::info!(lanes = spec.lanes, curves = spec.curves.len(), "road map received: lanes ahead from it");
        self.road = Some(Road::new(spec.clone()));
        self.road_s_m = None;
    }

    /// The ego's path curvature, from its yaw rate.
    fn curvature(ego: &EgoNow) -> f64 {
        ego.yaw_rate_radps / ego.speed_mps.max(2.0)
    }

    /// Takes a perception frame: updates the tracks, picks the lead and updates its estimate.
    ///
    /// A vehicle is in the ego's lane by its offset from the lane's centre: on the map's lane
    /// where there is a map (bends ahead included), else from the path the yaw rate predicts.
    pub fn perceive(&mut self, frame: &PerceptionFrame, ego: &EgoNow) {
        let front = self.s.vehicle.front_overhang_from_origin_m;
        let kappa = Self::curvature(ego);
        let lane_ahead = LaneAhead::find(self.road.as_ref(), &mut self.road_s_m, ego);
        let lane = &self.s.lane;
        // The limits are for a 3.5 m lane: on the map's lanes they move with its width (a car
        // riding 1.8 m off the centre of a 5 m lane is in it).
        let wider_m = lane_ahead.as_ref().map_or(0.0, |l| (l.road.lane_width_m() - SETTINGS_LANE_WIDTH_M) / 2.0);
        let (in_lane_m, stay_in_lane_m) = (lane.in_lane_m + wider_m, lane.stay_in_lane_m + wider_m);
        let current = self.lead.map(|l| l.id);
        // The nearest in the lane, and the nearest by the entry test alone (no hysteresis for
        // the current lead), with their gaps.
        let mut best: Option<(&Object, f64)> = None;
        let mut in_lane: Vec<(&Object, f64)> = Vec::new();
        for o in &frame.objects {
            let off = match &lane_ahead {
                Some(l) => l.offset_m(o.distance_m, o.lateral_m),
                None => o.lateral_m - kappa * o.distance_m * o.distance_m / 2.0,
            };
            let track = Self::track(&mut self.tracks, o.id, off, frame.stamp_s);

            let gap = o.distance_m - front;
            if o.distance_m <= 0.0 || gap > lane.range_m {
                continue;
            }
            // Lateral speed counts once a track has a few frames behind it.
            let predicted = if track.seen >= 4 { off + track.lateral_rate_mps * lane.lateral_lookahead_s } else { off };
            let limit = if current == Some(o.id) { stay_in_lane_m } else { in_lane_m };
            let off = off.abs().min(predicted.abs());
            if off >= limit {
                continue;
            }
            if best.is_none_or(|b| gap < b.1) {
                best = Some((o, gap));
            }
            if off < in_lane_m {
                in_lane.push((o, gap));
            }
        }
        let nearest = |beyond_m: f64| {
            in_lane.iter().filter(|(_, gap)| *gap > beyond_m).min_by(|x, y| x.1.total_cmp(&y.1)).copied()
        };
        let entering = nearest(f64::NEG_INFINITY);
        // Beyond the lead, the nearest vehicle in the lane past it: the lead cannot drive
        // through it, so it counts for the threat too. A truck standing beyond a van that
        // moves out only at the last moment is braked for from when it is seen over the van,
        // not once the van has gone (a warranted 1.5-1.9 s emergency before, in a scenario of
        // our own). A vehicle beyond at the lead's speed or faster asks for nothing.
        let beyond = best.and_then(|(_, lead_gap)| nearest(lead_gap + BEYOND_LEAD_M));
        self.next_in_lane = match (best, entering) {
            (Some((b, _)), Some(e)) if e.0.id != b.id => Some(e),
            _ => beyond,
        }
        .map(|(o, gap_m)| Revealed { stamp_s: frame.stamp_s, gap_m, relative_speed_mps: o.relative_speed_mps });
        self.tracks.retain(|_, t| frame.stamp_s - t.stamp_s < 2.0);
        // A lead missing from a frame (far away a detector misses one now and then) is kept,
        // moving on as estimated, for LEAD_COAST_S unless a nearer vehicle is in the lane:
        // taking it anew would lose its speed estimate, which takes tenths of a second to
        // measure again at long range. A lead seen outside the lane is let go at once. A settled
        // lead standing still is kept for STANDING_COAST_S: it cannot have driven off, only be
        // hidden (just past a bend's exit, a car standing in the ego's lane went missing for
        // 1.6 s at 100-137 m behind cars standing in the lanes either side; the ACC resumed its
        // cruise meanwhile and, seeing it again, needed a 5 s emergency at up to 5.4 m/s2).
        let missed = self.lead.filter(|f| {
            let coast_s = if f.settled() && f.x[1] < STANDING_LEAD_MPS { STANDING_COAST_S } else { LEAD_COAST_S };
            !frame.objects.iter().any(|o| o.id == f.id)
                && frame.stamp_s - f.seen_s < coast_s
                && best.is_none_or(|b| b.1 > f.x[0])
        });
        if missed.is_some() {
            return;
        }
        let Some((o, gap)) = best else {
            if current.is_some() {
                tracing::debug!(from = ?current, "lead lost");
            }
            self.lead = None;
            return;
        };
        self.follow(o, gap, ego, frame.stamp_s, current);
    }

    /// The track of object `id` seen at lateral offset `off` at `stamp_s`, updated and kept:
    /// the rate of that same offset (in a bend a car standing in the next lane sweeps across
    /// the ego's own frame as the ego turns, not across its lane).
    fn track(tracks: &mut HashMap<u32, Track>, id: u32, off: f64, stamp_s: f64) -> Track {
        let track = match tracks.get(&id) {
            Some(t) if stamp_s > t.stamp_s => {
                let lat_rate =
                    ((off - t.lateral_m) / (stamp_s - t.stamp_s)).clamp(-MAX_LATERAL_RATE_MPS, MAX_LATERAL_RATE_MPS);
                Track {
                    stamp_s,
                    lateral_m: off,
                    lateral_rate_mps: t.lateral_rate_mps + RATE_FILTER * (lat_rate - t.lateral_rate_mps),
                    seen: t.seen.saturating_add(1),
                }
            }
            Some(t) => *t,
            None => Track { stamp_s, lateral_m: off, lateral_rate_mps: 0.0, seen: 1 },
        };
        tracks.insert(id, track);
        track
    }

    /// Follows `o` at `gap` as the lead: updates its estimate, or starts a new one when the
    /// lead changed (`current` was the lead before this frame).
    fn follow(&mut self, o: &Object, gap: f64, ego: &EgoNow, stamp_s: f64, current: Option<u32>) {
        let n = self.noise;
        let t = ego.t_s.max(stamp_s);
        let speed = ego.speed_mps + o.relative_speed_mps;
        // The speed's noise is the model's for this range (the figures the ride was tuned
        // with); while a lead is new, perception's own estimate when larger: a new track's
        // speed is a guess until a few frames have measured it (tens of m/s at first, far
        // away).
        let speed_sigma =
            |settled: bool| n.speed_sigma(gap).max(if settled { 0.0 } else { o.relative_speed_sigma_mps });
        match &mut self.lead {
            Some(f) if f.id == o.id => {
                f.predict(t, ego.speed_mps, n.jerk_sigma_mps3);
                f.brake_lights(o.brake_lights);
                f.seen_s = stamp_s;
                f.update(0, gap, n.gap_sigma(gap));
                f.update_speed(speed, speed_sigma(f.settled()), n.speed_steady(gap));
            }
            _ => {
                tracing::debug!(from = ?current, to = o.id, "lead changed");
                self.lead = Some(LeadFilter::new(o.id, t, gap, speed.max(0.0), speed_sigma(false), &n));
            }
        }
    }

    /// One control step. `warnings` are the node's findings about its inputs (stale speed or
    /// perception, perception lost); any of them puts the ACC in Stale mode.
    pub fn step(&mut self, ego: &EgoNow, warnings: &[AccWarning]) -> Output {
        let dt = self.last_t_s.map_or(0.0, |t| (ego.t_s - t).clamp(0.0, 0.2));
        self.last_t_s = Some(ego.t_s);
        let v = ego.speed_mps.max(0.0);
        let mut warnings: Vec<AccWarning> = warnings.to_vec();
        let stale = !warnings.is_empty();

        let lead = self.lead_now(ego.t_s, v, stale);
        let desired_gap = self.s.standstill_m + self.time_gap_s * v;
        let revealed = self.next_in_lane.filter(|_| lead.is_some()).map(|r| {
            let rel = r.relative_speed_mps;
            let gap = r.gap_m + rel * (ego.t_s - r.stamp_s).max(0.0);
            threat(gap, v, (v + rel).max(0.0), 0.0)
        });
        let threat = lead
            .map(|l| threat(l.gap_m, v, l.speed_mps, l.threat_accel()))
            .map(|t| revealed.map_or(t, |r| t.or_worse(&r)));
        if threat.is_some_and(|t| self.warns(&t, v)) {
            warnings.push(AccWarning::ForwardCollision);
        }

        let (mode, accel) = if !self.enabled {
            (self.emergency, self.hard_lead) = (false, None);
            (AccMode::Off, 0.0)
        } else if stale {
            (self.emergency, self.hard_lead) = (false, None);
            // From the last command to the stale deceleration within the jerk limit, from either
            // side: no jolt when perception drops out for a moment (a burst of lost frames),
            // whether the car was accelerating or braking harder than the stale deceleration.
            let (from, step) = (self.accel_cmd, self.s.limits.jerk_mps3 * dt);
            (AccMode::Stale, (-self.s.stale.decel_mps2).clamp(from - step, from + step))
        } else {
            // A lead braking harder than comfort allows is answered at once, at what it takes.
            // Once found so, it stays so until it brakes less than the comfort limit by
            // HARD_BRAKING_RELEASE_MPS2: an estimate wandering about the threshold while the
            // lead's deceleration builds made the emergency flicker in and out (with ground
            // truth and a noisy speed reading, an emergency of 50 ms, over before the lead's
            // deceleration had passed the limit, then another). Without its lamps lit, the
            // estimate less one standard deviation must say so (`LeadNow::threat_accel`): a
            // truck 160 m ahead in a bend, its speed read to +-3 m/s, was estimated at
            // -6.4 m/s2 (sigma 5.1) for a moment and drew an emergency.
            let hard = lead.filter(|l| l.settled && l.speed_mps > HARD_BRAKING_MIN_SPEED_MPS).is_some_and(|l| {
                let limit = self.s.limits.decel_mps2;
                l.threat_accel() < -limit - self.noise.hard_braking_margin_mps2
                    || (self.hard_lead == Some(l.id) && l.accel_mps2 < -limit + HARD_BRAKING_RELEASE_MPS2)
            });
            self.hard_lead = lead.filter(|_| hard).map(|l| l.id);
            self.update_emergency(threat.as_ref(), hard, v, ego.t_s);
            match threat.filter(|_| self.emergency) {
                Some(t) => (AccMode::Emergency, -self.emergency_decel(&t, hard)),
                None => {
                    let guard = self.comfort_guard(lead, threat, revealed, v);
                    self.comfort_target(v, lead, guard.as_ref(), desired_gap, dt)
                }
            }
        };
        // The actuators lag: ask for the target plus lag x its rate of change, so the applied
        // acceleration follows a ramping target instead of trailing it (a jump, as into an
        // emergency, is not anticipated beyond twice the jerk limit).
        let rate_limit = 2.0 * self.s.limits.jerk_mps3;
        let rate = if dt > 0.0 { ((accel - self.accel_cmd) / dt).clamp(-rate_limit, rate_limit) } else { 0.0 };
        let lead_accel = self.params.actuator_lag_s * rate;
        self.accel_cmd = accel;

        let (throttle, brake) = self.actuate(mode, accel, lead_accel, v, ego.accel_mps2, dt);
        let status = AccStatus {
            mode,
            set_speed_mps: self.set_speed_mps,
            time_gap_s: self.time_gap_s,
            target_accel_mps2: accel,
            lead: lead.map(|l| LeadInfo {
                id: l.id,
                gap_m: l.gap_m,
                desired_gap_m: desired_gap,
                relative_speed_mps: l.speed_mps - v,
                ttc_s: threat.and_then(|t| t.ttc_s),
            }),
            warnings,
        };
        Output { throttle, brake, status }
    }

    /// The lead now: its gap moved on from the frame's time at the measured relative speed.
    /// None while stale: the watchdog's clock is a guess, and the estimate is not used then
    /// (it catches up when fresh data return).
    fn lead_now(&mut self, t_s: f64, v: f64, stale: bool) -> Option<LeadNow> {
        if stale {
            return None;
        }
        let f = self.lead.as_mut()?;
        f.predict(t_s, v, self.noise.jerk_sigma_mps3);
        let f = *f;
        let l = LeadNow {
            id: f.id,
            gap_m: f.x[0],
            speed_mps: f.x[1].max(0.0),
            accel_mps2: f.x[2],
            speed_sigma_mps: f.p[(1, 1)].max(0.0).sqrt(),
            accel_sigma_mps2: f.p[(2, 2)].max(0.0).sqrt(),
            brake_lights: f.brake_lights,
            lamps_vouch: f.lamps_vouch(),
            lit_for_s: f.lit_for_s(),
            settled: f.settled(),
            followed_s: f.t_s - f.since_s,
            speed_noise_mps: f.speed_noise_mps(),
        };
        tracing::trace!(
            t_s,
            gap_m = l.gap_m,
            speed_mps = l.speed_mps,
            accel_mps2 = l.accel_mps2,
            accel_sigma_mps2 = l.accel_sigma_mps2,
            brake_lights = l.brake_lights,
            speed_noise_mps = l.speed_noise_mps,
            last_target_mps2 = self.accel_cmd,
            "lead"
        );
        Some(l)
    }

    /// What comfort braking plans for: the threat, or a worse one while the lead's speed or
    /// its braking is not yet measured (below).
    fn comfort_guard(
        &self,
        lead: Option<LeadNow>,
        threat: Option<Threat>,
        revealed: Option<Threat>,
        v: f64,
    ) -> Option<Threat> {
        // A new lead's speed is still being measured (far ahead, a camera needs a
        // few tenths of a second): comfort braking plans for it being slower by
        // UNMEASURED_SIGMAS of its uncertainty, so a standing car seen at the edge
        // of range is braked for from the first frames, not once its speed is
        // known. Only where comfort braking could cope with that case: a car
        // cutting in near, its speed not yet measured, is no standing car to brake
        // hard for. An emergency still needs the estimate itself.
        //
        // Likewise for LIT_ANTICIPATION_S after a lead's brake lights come on:
        // the lamps say the pedal is pressed, its speed says how hard only some
        // tenths of a second later (a camera's range moves by centimetres while
        // the deceleration builds). Comfort braking plans for the lead braking at
        // the comfort limit meanwhile, so the ego eases into braking with the lamps
        // instead of once the deceleration shows; the estimate decides after. Only
        // where such a brake would need much of the comfort braking (at speed, or
        // close): slow and far back, a late answer costs nothing, and braking for
        // every touch of the lead's pedal would cost the time gap.
        let decel = self.s.limits.decel_at(v);
        let worse_within_comfort = |t: Threat, worse: Threat| {
            if worse.needed_decel_mps2 <= decel {
                t.or_worse(&worse)
            } else {
                t
            }
        };
        match lead {
            Some(l) if !l.settled => {
                let slower_mps = (l.speed_mps - UNMEASURED_SIGMAS * l.speed_sigma_mps).max(0.0);
                let slower = |gap_m: f64| self::threat(gap_m, v, slower_mps, l.threat_accel());
                // A new lead beyond twice the time gap is braked for before it is
                // settled only where waiting would cost comfort: were it that slow,
                // the room the wait takes must leave the stop well within the
                // comfort limit. Far away a lead may be no vehicle: in a bend, two
                // cars standing in the lanes either side 200 m ahead merged in the
                // image into one in the ego's lane for half a second, read as
                // standing, and drew 1.2-1.4 m/s2 for nothing. The follow law still
                // answers it, and an emergency still reads the threat itself. The
                // price: a car standing far ahead is braked for up to a second
                // later and harder (cut-out-revealing-stopped-car 3.1 -> 4.0 m/s2,
                // within the limit at its speed). Nearer, nothing waits.
                let far = l.gap_m > self.s.standstill_m + FAR_TIME_GAPS * self.time_gap_s * v;
                let wait_s = (SETTLE_S - l.followed_s).max(0.0);
                let waited = slower(l.gap_m - (v - slower_mps).max(0.0) * wait_s);
                if far && waited.needed_decel_mps2 <= UNSETTLED_WAIT_SHARE * decel {
                    revealed
                } else {
                    threat.map(|t| worse_within_comfort(t, slower(l.gap_m)))
                }
            }
            Some(l) if l.lit_for_s.is_some_and(|s| s < LIT_ANTICIPATION_S) => threat.map(|t| {
                let braking = l.threat_accel().min(-self.s.limits.decel_mps2);
                let hard = self::threat(l.gap_m, v, l.speed_mps, braking);
                if hard.needed_decel_mps2 >= LIT_NEED_SHARE * decel {
                    worse_within_comfort(t, hard)
                } else {
                    t
                }
            }),
            _ => threat,
        }
    }

    /// The forward-collision warning: TTC below its threshold, or closing within
    /// release_ttc_s with more braking needed than comfort allows.
    fn warns(&self, t: &Threat, v: f64) -> bool {
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        ttc < self.s.emergency.warn_ttc_s || self.beyond_comfort(t, v)
    }

    /// Closing within release_ttc_s, with more braking needed than comfort allows at this
    /// speed and more than comfort braking from here on can give: from the deceleration asked
    /// now, at the jerk limit, up to the limit of each speed on the way down (which grows as
    /// the speed falls: a stop from 30 m/s 150 m ahead peaks near 4.9 m/s2 at 6 m/s).
    fn beyond_comfort(&self, t: &Threat, v: f64) -> bool {
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        ttc < self.s.emergency.release_ttc_s
            && t.needed_decel_mps2 > self.s.limits.decel_at(v)
            && !self.comfort_avoids(t, v)
    }

    /// Whether braking within the comfort limits from now on (the command ramping at the jerk
    /// limit to each speed's limit) keeps the threat's room, with the lead going on at its
    /// speed and deceleration to a stop. Simulated in 20 ms steps.
    fn comfort_avoids(&self, t: &Threat, v: f64) -> bool {
        const DT: f64 = 0.02;
        let lim = &self.s.limits;
        let lead_a = t.lead_accel_mps2.min(0.0);
        let (mut gap, mut v, mut a, mut lead_v) = (t.room_m, v, self.accel_cmd.min(0.0), t.lead_speed_mps);
        // 60 s of braking stops from any speed the ACC allows.
        for _ in 0..3000 {
            if gap < 0.0 {
                return false;
            }
            if v <= 0.0 || (v <= lead_v && (lead_a == 0.0 || lead_v == 0.0)) {
                return true;
            }
            a = (a - lim.jerk_mps3 * DT).max(-lim.decel_at(v));
            v = (v + a * DT).max(0.0);
            lead_v = (lead_v + lead_a * DT).max(0.0);
            gap += (lead_v - v) * DT;
        }
        true
    }

    /// Enters emergency braking when a collision is imminent (TTC below the threshold, or
    /// closing within release_ttc_s with more braking needed than comfort allows) or when the
    /// lead brakes harder than comfort allows (`hard_lead`) and stopping behind it needs real
    /// braking; leaves it at standstill or once the threat is comfortably over and the lead no
    /// longer brakes hard.
    fn update_emergency(&mut self, threat: Option<&Threat>, hard_lead: bool, v: f64, t_s: f64) {
        let Some(t) = threat else {
            self.emergency = false;
            return;
        };
        let (e, lim) = (&self.s.emergency, &self.s.limits);
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        let beyond_comfort = self.beyond_comfort(t, v);
        // Braking at 1.5 times a need near NEEDED_GUARD_MPS2 brakes beyond what a far lead
        // needs (ground truth, a car 140 m ahead braking hard to stop behind one standing: 1.5
        // m/s2 where 0.8-1.0 was needed, 0.9 s of phantom braking); the comfort guard answers
        // such a need within 0.7 s, and the emergency ends when the need falls below it.
        let hard_and_needed = hard_lead && t.needed_decel_mps2 > HARD_LEAD_EMERGENCY_FACTOR * NEEDED_GUARD_MPS2;
        // A short TTC alone is no emergency while the ego already brakes about as hard as the
        // threat needs: in a planned stop the TTC (at constant speeds) falls below any
        // threshold as the car comes to rest behind the lead.
        let behind_need = t.needed_decel_mps2 > -self.accel_cmd + UNDER_BRAKING_S * lim.jerk_mps3;
        let closing_fast = ttc < e.brake_ttc_s && behind_need;
        if !self.emergency && (closing_fast || beyond_comfort || hard_and_needed) {
            tracing::warn!(t_s, ttc_s = ttc, needed_decel_mps2 = t.needed_decel_mps2, hard_lead, "emergency braking");
            self.emergency = true;
        } else if self.emergency
            && (v < STANDSTILL_MPS
                || ((!hard_lead || t.needed_decel_mps2 < NEEDED_GUARD_MPS2)
                    && ttc > e.release_ttc_s
                    && t.needed_decel_mps2 < 0.8 * lim.decel_mps2))
        {
            tracing::info!(t_s, ttc_s = ttc, "emergency over");
            self.emergency = false;
        }
    }

    /// Emergency deceleration: the vehicle's maximum when TTC is below full_brake_ttc_s, else
    /// 1.5 times what the threat needs, at least the comfort limit once the gap closes fast
    /// (TTC below brake_ttc_s; behind a hard-braking lead still far enough, 1.5 times the need
    /// is enough).
    fn emergency_decel(&self, t: &Threat, hard_lead: bool) -> f64 {
        let vehicle_max = self.params.max_brake_decel_mps2;
        let ttc = t.ttc_s.unwrap_or(f64::INFINITY);
        if ttc < self.s.emergency.full_brake_ttc_s {
            return vehicle_max;
        }
        let floor = if hard_lead && ttc >= self.s.emergency.brake_ttc_s { 0.0 } else { self.s.limits.decel_mps2 };
        (HARD_LEAD_EMERGENCY_FACTOR * t.needed_decel_mps2).clamp(floor, vehicle_max)
    }

    /// The most the guard brakes for a threat: a vehicle beyond twice the time gap that the
    /// ego is not closing on fast (matching its speed short of the standstill distance needs
    /// less than FAR_CLOSING_MPS2) is answered by easing off, at most FAR_DECEL_MPS2, unless
    /// `lead` is seen braking harder than FAR_BRAKING_MPS2 with its lamps lit. Such a lead
    /// braking for a moment 4 s ahead (following its own lead) drew 1.6 m/s2 and then 1.45 m/s2
    /// of acceleration again (phantom braking, in a scenario of our own); one that keeps braking
    /// is soon near or closing fast, and braked for in full.
    fn far_cap_mps2(&self, t: &Threat, v: f64, lead: &LeadNow) -> f64 {
        let gap = t.room_m + THREAT_MARGIN_M;
        let room = (gap - self.s.standstill_m).max(0.1);
        let closing = (v - t.lead_speed_mps).max(0.0);
        let far = gap > self.s.standstill_m + FAR_TIME_GAPS * self.time_gap_s * v;
        // The lead as estimated, not as the guard may plan for it (braking at the comfort limit
        // while its lamps are new): planned for that far ahead, a touch of the pedal drew 1.3 m/s2.
        let easing = !lead.brake_lights || lead.threat_accel() > -FAR_BRAKING_MPS2;
        if far && easing && closing * closing / (2.0 * room) < FAR_CLOSING_MPS2 {
            FAR_DECEL_MPS2
        } else {
            f64::INFINITY
        }
    }

    /// Speed or Follow mode within the comfort limits: the lower of the cruise law and the
    /// time-gap law, moved toward from the last command at most at the jerk limit.
    fn comfort_target(
        &self,
        v: f64,
        lead: Option<LeadNow>,
        threat: Option<&Threat>,
        desired_gap: f64,
        dt: f64,
    ) -> (AccMode, f64) {
        let (g, lim) = (&self.s.gains, &self.s.limits);
        let decel = lim.decel_at(v);
        let cruise = (g.cruise_per_s * (self.set_speed_mps - v)).clamp(-decel, lim.accel_mps2);
        let follow = lead.map(|l| {
            let law = g.gap_per_s2 * (l.gap_m - desired_gap) + g.speed_per_s * (l.speed_mps - v);
            // Never less braking than avoiding a collision needs, once it matters: a lead easing
            // off a little (or the noise in its estimated deceleration) is the law's to answer;
            // below NEEDED_GUARD_MPS2 the guard made the car dip for nothing.
            let needed = threat.map_or(0.0, |t| t.needed_decel_mps2);
            let mut a = match threat {
                Some(t) if needed > NEEDED_GUARD_MPS2 => law.min(-needed.min(self.far_cap_mps2(t, v, &l))),
                _ => law,
            };
            // At standstill: stay until the lead has moved off.
            if v < STANDSTILL_MPS && !(l.gap_m > self.s.standstill_m + 1.0 && l.speed_mps > 0.5) {
                a = a.min(-0.5);
            }
            a
        });
        let (mode, target) = match follow {
            Some(f) if f < cruise => (AccMode::Follow, f),
            _ => (AccMode::Speed, cruise),
        };
        let target = target.clamp(-decel, lim.accel_mps2);
        let step = lim.jerk_mps3 * dt;
        (mode, target.clamp(self.accel_cmd - step, self.accel_cmd + step))
    }

    /// The low-level loop: the vehicle model's throttle/brake for the target (plus `lead`, the
    /// actuator lag's compensation), plus an integrator on the acceleration error for what the
    /// model does not know.
    fn actuate(&mut self, mode: AccMode, accel: f64, lead: f64, v: f64, measured: f64, dt: f64) -> (f32, f32) {
        match mode {
            AccMode::Off => {
                self.integral = 0.0;
                self.last_throttle = 0.0;
                return (0.0, 0.0);
            }
            AccMode::Emergency => {
                self.integral = 0.0;
                if accel <= -self.params.max_brake_decel_mps2 {
                    self.last_throttle = 0.0;
                    return (0.0, 1.0);
                }
            }
            _ => {
                if v > 1.0 && accel.abs() < self.s.limits.decel_mps2 {
                    self.integral = (self.integral + LOW_LEVEL_KI * (accel - measured) * dt)
                        .clamp(-LOW_LEVEL_I_MAX, LOW_LEVEL_I_MAX);
                }
            }
        }
        let (mut throttle, brake) = actuate_acceleration(&self.params, v, accel + lead + self.integral);
        if mode == AccMode::Stale {
            // Inputs too old: the throttle only goes down (it follows the eased target).
            throttle = throttle.min(self.last_throttle);
        }
        self.last_throttle = throttle;
        if v < STANDSTILL_MPS && accel <= 0.0 {
            self.last_throttle = 0.0;
            return (0.0, (brake as f32).max(HOLD_BRAKE));
        }
        (throttle as f32, brake as f32)
    }
}
