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
use super::road::Road;
use super::scenario::Action;
use crate::vehicle::actuate_acceleration;
use crate::vehicle::VehicleParams;

/// Where a vehicle is and how it moves, as a driver sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Rear axle along the road and across it.
    pub s_m: f64,
    pub d_m: f64,
    pub rear_axle: Vector2<f64>,
    pub yaw_rad: f64,
    pub speed_mps: f64,
}

/// The nearest vehicle ahead that overlaps this one's path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lead {
    /// Bumper to bumper.
    pub gap_m: f64,
    pub speed_mps: f64,
}

/// Time gap and standstill distance traffic keeps to the vehicle ahead.
const FOLLOW_TIME_GAP_S: f64 = 1.4;
const FOLLOW_STANDSTILL_M: f64 = 4.0;

/// Steering that pursues the point `lookahead` ahead on the road at lateral offset `d_target`.
pub fn pursue(params: &VehicleParams, road: &Road, me: &Observation, d_target: f64) -> f64 {
    let lookahead = (me.speed_mps * 1.0).max(8.0);
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
pub struct Cruise {
    pub target_mps: f64,
    /// Acceleration or deceleration used to reach `target_mps`.
    pub ramp_mps2: f64,
    /// The reference speed, moving toward the target at the ramp rate.
    pub reference_mps: f64,
}

impl Cruise {
    pub fn new(speed_mps: f64) -> Self {
        Cruise { target_mps: speed_mps, ramp_mps2: 2.0, reference_mps: speed_mps }
    }

    /// Throttle and brake for this step.
    pub fn longitudinal(
        &mut self,
        params: &VehicleParams,
        speed_mps: f64,
        lead: Option<Lead>,
        dt_s: f64,
    ) -> (f64, f64) {
        let step = self.ramp_mps2 * dt_s;
        let diff = self.target_mps - self.reference_mps;
        let ramp_accel = if diff.abs() <= step { 0.0 } else { self.ramp_mps2.copysign(diff) };
        self.reference_mps += diff.clamp(-step, step);
        let mut accel = ramp_accel + 1.0 * (self.reference_mps - speed_mps);
        if let Some(lead) = lead {
            let desired = FOLLOW_STANDSTILL_M + FOLLOW_TIME_GAP_S * speed_mps;
            let follow = 0.3 * (lead.gap_m - desired) + 0.9 * (lead.speed_mps - speed_mps);
            accel = accel.min(follow);
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
pub struct Wander {
    pub mean_interval_s: f64,
    pub lanes: Vec<u32>,
    pub next_s: f64,
    pub rng: SimRng,
}

/// What a traffic driver sees of the others when it considers a lane change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Neighbour {
    pub s_m: f64,
    pub lane: i32,
}

/// A scripted traffic driver.
#[derive(Debug, Clone)]
pub struct TrafficDriver {
    pub cruise: Cruise,
    pub follow: bool,
    lane: u32,
    lane_change: Option<LaneChange>,
    /// Actions not yet started, in file order.
    pending: Vec<Action>,
    wander: Option<Wander>,
}

impl TrafficDriver {
    pub fn new(lane: u32, speed_mps: f64, follow: bool, actions: Vec<Action>, wander: Option<Wander>) -> Self {
        TrafficDriver { cruise: Cruise::new(speed_mps), follow, lane, lane_change: None, pending: actions, wander }
    }

    /// The lane the driver is in or heading to.
    pub fn lane(&self) -> u32 {
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
            if let Some(lane) = a.lane {
                self.change_lane(road, me, lane, t_s, a.duration_s);
            }
        }
    }

    fn change_lane(&mut self, road: &Road, me: &Observation, lane: u32, t_s: f64, duration_s: f64) {
        let from_d = self.lane_change.map_or(me.d_m, |c| c.d_at(t_s));
        self.lane = lane;
        self.lane_change = Some(LaneChange { from_d, to_d: road.lane_center_d(lane), start_s: t_s, duration_s });
    }

    /// Considers a random lane change: to a neighbouring allowed lane with room around.
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
        let room = |lane: u32| {
            others.iter().all(|o| o.lane != lane as i32 || !(me.s_m - 20.0..me.s_m + 30.0).contains(&o.s_m))
        };
        match target.filter(|l| room(*l)) {
            Some(lane) => {
                w.next_s = t_s + w.mean_interval_s * (0.5 + w.rng.unit());
                self.change_lane(road, me, lane, t_s, 4.0);
            }
            // No room now: look again a little later.
            None => w.next_s = t_s + 2.0,
        }
    }

    /// This step's actuation.
    #[allow(clippy::too_many_arguments)]
    pub fn drive(
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
        let lead = if self.follow { lead } else { None };
        let (throttle, brake) = self.cruise.longitudinal(params, me.speed_mps, lead, dt_s);
        let d_target = self.lane_change.map_or(road.lane_center_d(self.lane), |c| c.d_at(t_s));
        Actuation { throttle, brake, steer: pursue(params, road, me, d_target) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lane_change_moves_smoothly_from_one_lane_to_the_other() {
        let c = LaneChange { from_d: 0.0, to_d: 3.5, start_s: 10.0, duration_s: 4.0 };
        assert_eq!(c.d_at(9.0), 0.0);
        assert_eq!(c.d_at(12.0), 1.75);
        assert_eq!(c.d_at(20.0), 3.5);
    }
}
