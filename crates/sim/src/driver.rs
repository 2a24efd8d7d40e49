//! Drivers: how traffic vehicles (and the ego before any controller speaks) turn a plan into
//! throttle, brake and steer. Pure code on road coordinates.
//!
//! Longitudinal: a target speed reached at a set acceleration (the scenario's speed actions)
//! gives a reference speed ramp; following the vehicle ahead (constant time gap) can only
//! lower the demanded acceleration; an inverse of the vehicle model turns the demanded
//! acceleration into throttle or brake. Lateral: pure pursuit of a point ahead on the target
//! lateral offset, which moves smoothly from one lane to the next during a lane change.

use nalgebra::Vector2;

use super::dynamics::Actuation;
use super::rng::SimRng;
use super::scenario::Action;
use slipstream_model::road::Road;
use slipstream_model::vehicle::{actuate_acceleration, lag_toward, VehicleParams};

/// Where a vehicle is and how it moves, as a driver sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Observation {
    pub id: u32,
    /// Rear axle along the road and across it.
    pub s_m: f64,
    pub d_m: f64,
    pub rear_axle: Vector2<f64>,
    pub yaw_rad: f64,
    pub speed_mps: f64,
}

/// The nearest vehicle ahead that overlaps this one's path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Lead {
    /// Bumper to bumper.
    pub gap_m: f64,
    pub speed_mps: f64,
}

/// Time gap and standstill distance traffic keeps to the vehicle ahead.
const FOLLOW_TIME_GAP_S: f64 = 1.4;
const FOLLOW_STANDSTILL_M: f64 = 4.0;

/// The gap acceptance of a random lane change (a MOBIL-like safety criterion): after it,
/// neither the new follower in the target lane nor the changer itself behind its new leader
/// may need to brake harder than this, by the traffic's own following law.
pub(crate) const LANE_CHANGE_SAFE_DECEL_MPS2: f64 = 2.0;
/// ... and no bumper comes closer than this.
const LANE_CHANGE_MIN_GAP_M: f64 = 3.0;
/// A driver in a lane that ends moves over from this far before its taper begins, when the
/// gap beside is safe (looking again every step); until it has, it stops short of the taper's
/// middle as behind a standing vehicle.
const MERGE_AHEAD_M: f64 = 250.0;

/// The acceleration traffic asks for behind a lead `gap_m` ahead (bumper to bumper).
fn follow_accel(speed_mps: f64, lead_gap_m: f64, lead_speed_mps: f64) -> f64 {
    let desired = FOLLOW_STANDSTILL_M + FOLLOW_TIME_GAP_S * speed_mps;
    0.3 * (lead_gap_m - desired) + 0.9 * (lead_speed_mps - speed_mps)
}

/// How far ahead on the road `pursue` aims.
fn lookahead_m(speed_mps: f64) -> f64 {
    speed_mps.max(8.0)
}

/// Steering that pursues the point `lookahead` ahead on the road at lateral offset `d_target`.
pub(crate) fn pursue(params: &VehicleParams, road: &Road, me: &Observation, d_target: f64) -> f64 {
    let lookahead = lookahead_m(me.speed_mps);
    let target = road.to_world(me.s_m + lookahead, d_target) - me.rear_axle;
    let (sin, cos) = me.yaw_rad.sin_cos();
    let x = target.x * cos + target.y * sin;
    let y = -target.x * sin + target.y * cos;
    let curvature = 2.0 * y / (x * x + y * y).max(1e-6);
    ((curvature * params.wheelbase_m).atan() / params.max_steer_rad).clamp(-1.0, 1.0)
}

/// Holds a speed (with optional following) and a lane: the ego's stand-in before a controller
/// sends its first command, and the base of every traffic driver.
#[derive(Debug, Clone)]
pub(crate) struct Cruise {
    pub target_mps: f64,
    /// Acceleration or deceleration used to reach `target_mps`.
    pub ramp_mps2: f64,
    /// The reference speed, moving toward the target at the ramp rate.
    pub reference_mps: f64,
    /// The reference's acceleration (the ramp rate through the actuator lag).
    pub reference_accel: f64,
}

impl Cruise {
    pub(crate) fn new(speed_mps: f64) -> Self {
        Cruise { target_mps: speed_mps, ramp_mps2: 2.0, reference_mps: speed_mps, reference_accel: 0.0 }
    }

    /// Throttle and brake for this step.
    pub(crate) fn longitudinal(
        &mut self,
        params: &VehicleParams,
        speed_mps: f64,
        lead: Option<Lead>,
        dt_s: f64,
    ) -> (f64, f64) {
        // The reference speed ramps toward the target as the vehicle can: its acceleration
        // builds up through the actuator lag, so the speed error stays small and no catch-up
        // overshoots the scripted rate.
        let diff = self.target_mps - self.reference_mps;
        let wanted = if diff.abs() <= self.ramp_mps2 * dt_s { 0.0 } else { self.ramp_mps2.copysign(diff) };
        let lagged = lag_toward(self.reference_accel, wanted, params.actuator_lag_s, dt_s);
        let change = lagged - self.reference_accel;
        self.reference_accel = lagged;
        let dv = self.reference_accel * dt_s;
        // Never past the target.
        self.reference_mps += if dv * diff > 0.0 { dv.abs().min(diff.abs()).copysign(diff) } else { dv };
        // Asking for the reference's acceleration plus lag x its rate makes the wheels give it
        // (the lag inverted for a smooth signal).
        let lag_lead = params.actuator_lag_s * change / dt_s;
        let mut accel = self.reference_accel + lag_lead + 1.0 * (self.reference_mps - speed_mps);
        if let Some(lead) = lead {
            accel = accel.min(follow_accel(speed_mps, lead.gap_m, lead.speed_mps));
        }
        let accel = accel.clamp(-params.max_brake_decel_mps2, 3.0);
        if self.reference_mps < 0.05 && speed_mps < 0.5 && accel <= 0.0 {
            // Standing still: hold the brake rather than creep.
            return (0.0, 0.4);
        }
        actuate_acceleration(params, speed_mps, accel)
    }
}

/// A lane change under way: the lateral target moves from `from_d` to `to_d`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LaneChange {
    from_d: f64,
    to_d: f64,
    start_s: f64,
    duration_s: f64,
}

impl LaneChange {
    fn d_at(&self, t_s: f64) -> f64 {
        let x = ((t_s - self.start_s) / self.duration_s).clamp(0.0, 1.0);
        let smooth = x * x * (3.0 - 2.0 * x);
        self.from_d + (self.to_d - self.from_d) * smooth
    }
}

/// Random lane changes of generated traffic.
#[derive(Debug, Clone)]
pub(crate) struct Wander {
    pub mean_interval_s: f64,
    pub lanes: Vec<u32>,
    pub next_s: f64,
    pub rng: SimRng,
}

/// What a traffic driver sees of the others when it considers a lane change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Neighbour {
    pub id: u32,
    /// Along-road positions of the rear and front bumpers.
    pub rear_m: f64,
    pub front_m: f64,
    pub lane: i32,
    /// The lane it is changing to (its lane when it keeps it): a vehicle changing lanes
    /// claims both.
    pub target_lane: i32,
    pub speed_mps: f64,
}

/// Whether moving into `lane` is safe for everyone: the nearest vehicle behind in that lane
/// (the new follower) and the changer behind the nearest one ahead (its new leader) each need
/// at most LANE_CHANGE_SAFE_DECEL_MPS2 by the following law, with LANE_CHANGE_MIN_GAP_M
/// between bumpers. `me` is the changer as a neighbour.
pub(crate) fn safe_to_enter(me: &Neighbour, lane: u32, others: &[Neighbour]) -> bool {
    let in_lane = others.iter().filter(|o| (o.lane == lane as i32 || o.target_lane == lane as i32) && o.id != me.id);
    let follower = in_lane.clone().filter(|o| o.front_m <= me.front_m).max_by(|a, b| a.front_m.total_cmp(&b.front_m));
    let leader = in_lane.filter(|o| o.front_m > me.front_m).min_by(|a, b| a.rear_m.total_cmp(&b.rear_m));
    let follower_ok = follower.is_none_or(|f| {
        let gap = me.rear_m - f.front_m;
        gap >= LANE_CHANGE_MIN_GAP_M && follow_accel(f.speed_mps, gap, me.speed_mps) >= -LANE_CHANGE_SAFE_DECEL_MPS2
    });
    let leader_ok = leader.is_none_or(|l| {
        let gap = l.rear_m - me.front_m;
        gap >= LANE_CHANGE_MIN_GAP_M && follow_accel(me.speed_mps, gap, l.speed_mps) >= -LANE_CHANGE_SAFE_DECEL_MPS2
    });
    follower_ok && leader_ok
}

/// A scripted traffic driver.
#[derive(Debug, Clone)]
pub(crate) struct TrafficDriver {
    pub cruise: Cruise,
    pub follow: bool,
    lane: u32,
    /// Where across the lane it drives, from the lane's centre (positive left).
    offset_m: f64,
    lane_change: Option<LaneChange>,
    /// Actions not yet started, in file order.
    pending: Vec<Action>,
    wander: Option<Wander>,
}

impl TrafficDriver {
    pub(crate) fn new(
        lane: u32,
        offset_m: f64,
        speed_mps: f64,
        follow: bool,
        actions: Vec<Action>,
        wander: Option<Wander>,
    ) -> Self {
        TrafficDriver {
            cruise: Cruise::new(speed_mps),
            follow,
            lane,
            offset_m,
            lane_change: None,
            pending: actions,
            wander,
        }
    }

    /// Where across the road the driver holds the vehicle when not changing lanes.
    fn own_d(&self, road: &Road) -> f64 {
        road.lane_center_d(self.lane) + self.offset_m
    }

    /// The lane the driver is in or heading to.
    pub(crate) fn lane(&self) -> u32 {
        self.lane
    }

    /// Starts every action whose trigger fired: at `t_s`, or with the ego within its gap.
    fn start_actions(&mut self, road: &Road, me: &Observation, t_s: f64, gap_to_ego_m: f64) {
        let mut i = 0;
        while i < self.pending.len() {
            let a = &self.pending[i];
            let fired = a.at_s.is_some_and(|at| t_s >= at) || a.when_gap_m.is_some_and(|g| gap_to_ego_m <= g);
            if !fired {
                i += 1;
                continue;
            }
            let a = self.pending.remove(i);
            if let Some(v) = a.speed_mps {
                self.cruise.target_mps = v;
                self.cruise.ramp_mps2 = a.accel_mps2;
            }
            if a.lane.is_some() || a.offset_m.is_some() {
                self.offset_m = a.offset_m.unwrap_or(self.offset_m);
                self.change_lane(road, me, a.lane.unwrap_or(self.lane), t_s, a.duration_s);
            }
        }
    }

    fn change_lane(&mut self, road: &Road, me: &Observation, lane: u32, t_s: f64, duration_s: f64) {
        let from_d = self.lane_change.map_or(me.d_m, |c| c.d_at(t_s));
        self.lane = lane;
        self.lane_change = Some(LaneChange { from_d, to_d: self.own_d(road), start_s: t_s, duration_s });
    }

    /// Considers a random lane change: to a neighbouring allowed lane where the gap is safe.
    /// `others` holds this vehicle too (by its id).
    fn wander(&mut self, road: &Road, me: &Observation, t_s: f64, others: &[Neighbour]) {
        let Some(w) = &mut self.wander else { return };
        if t_s < w.next_s || self.lane_change.is_some_and(|c| t_s < c.start_s + c.duration_s) {
            return;
        }
        let options: Vec<u32> = [self.lane.checked_sub(1), Some(self.lane + 1)]
            .into_iter()
            .flatten()
            .filter(|l| w.lanes.contains(l))
            .collect();
        let target = options.get(w.rng.below(options.len() as u64) as usize).copied();
        let myself = others.iter().find(|o| o.id == me.id);
        match target.filter(|l| myself.is_some_and(|m| safe_to_enter(m, *l, others))) {
            Some(lane) => {
                w.next_s = t_s + w.mean_interval_s * (0.5 + w.rng.unit());
                self.change_lane(road, me, lane, t_s, 4.0);
            }
            // No room now: look again a little later.
            None => w.next_s = t_s + 2.0,
        }
    }

    /// In a lane that ends, within MERGE_AHEAD_M of its taper: the lane beside it when the
    /// gap there is safe. A vehicle that stands (target speed 0) stays where it is.
    fn merge_before_end(&mut self, road: &Road, me: &Observation, t_s: f64, others: &[Neighbour]) {
        let Some(end) = road.lane_end(self.lane) else { return };
        if self.cruise.target_mps <= 0.5 || me.s_m < end.end_m - end.taper_m - MERGE_AHEAD_M {
            return;
        }
        let inward = if self.lane == 0 { 1 } else { self.lane - 1 };
        if others.iter().find(|o| o.id == me.id).is_some_and(|m| safe_to_enter(m, inward, others)) {
            self.offset_m = 0.0;
            self.change_lane(road, me, inward, t_s, 4.0);
        }
    }

    /// This step's actuation.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn drive(
        &mut self,
        params: &VehicleParams,
        road: &Road,
        me: &Observation,
        lead: Option<Lead>,
        gap_to_ego_m: f64,
        others: &[Neighbour],
        t_s: f64,
        dt_s: f64,
    ) -> Actuation {
        self.start_actions(road, me, t_s, gap_to_ego_m);
        self.wander(road, me, t_s, others);
        self.merge_before_end(road, me, t_s, others);
        let mut lead = if self.follow { lead } else { None };
        // Not over yet: the lane's end stands ahead (stop short of the taper's middle).
        if let Some(end) = road.lane_end(self.lane) {
            let front = me.s_m + params.size_m[0] - params.rear_overhang_m;
            let gap_m = end.end_m - end.taper_m / 2.0 - front;
            if lead.is_none_or(|l| gap_m < l.gap_m) {
                lead = Some(Lead { gap_m, speed_mps: 0.0 });
            }
        }
        let (throttle, brake) = self.cruise.longitudinal(params, me.speed_mps, lead, dt_s);
        // During a lane change the pursued point is where the change should have the vehicle
        // once it gets there (the lookahead's time ahead): so the move takes its duration_s,
        // where aiming at today's offset lagged it by about as much again.
        let preview_s = lookahead_m(me.speed_mps) / me.speed_mps.max(1.0);
        let d_target = self.lane_change.map_or(self.own_d(road), |c| c.d_at(t_s + preview_s));
        Actuation { throttle, brake, steer: pursue(params, road, me, d_target) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(id: u32, front_m: f64, lane: i32, speed_mps: f64) -> Neighbour {
        Neighbour { id, rear_m: front_m - 4.6, front_m, lane, target_lane: lane, speed_mps }
    }

    #[test]
    fn a_gap_is_taken_only_when_nobody_must_brake_hard_for_it() {
        let me = car(0, 100.0, 1, 25.0);
        // A faster car 15 m behind in the target lane would have to brake hard; 90 m back it
        // has time; a slower one 25 m behind is no problem.
        assert!(!safe_to_enter(&me, 2, &[me, car(1, 80.4, 2, 32.0)]));
        assert!(safe_to_enter(&me, 2, &[me, car(1, 5.4, 2, 32.0)]));
        assert!(safe_to_enter(&me, 2, &[me, car(1, 70.4, 2, 20.0)]));
        // A slow car just ahead in the target lane: the changer would have to brake hard.
        assert!(!safe_to_enter(&me, 2, &[me, car(1, 112.0, 2, 15.0)]));
        // Side by side: no gap at all.
        assert!(!safe_to_enter(&me, 2, &[me, car(1, 101.0, 2, 25.0)]));
        // A car changing from lane 3 into lane 2 beside us claims lane 2 too.
        let merging = Neighbour { target_lane: 2, ..car(1, 101.0, 3, 25.0) };
        assert!(!safe_to_enter(&me, 2, &[me, merging]));
        // Another lane is nobody's concern.
        assert!(safe_to_enter(&me, 0, &[me, car(1, 101.0, 2, 25.0)]));
    }

    #[test]
    fn lane_change_moves_smoothly_from_one_lane_to_the_other() {
        let c = LaneChange { from_d: 0.0, to_d: 3.5, start_s: 10.0, duration_s: 4.0 };
        assert_eq!(c.d_at(9.0), 0.0);
        assert_eq!(c.d_at(12.0), 1.75);
        assert_eq!(c.d_at(20.0), 3.5);
    }
}
