//! The objects message: every other vehicle as the simulator knows it, matched to one camera
//! frame (same step, same simulation time) through the renderer's visibility report.

use nalgebra::{Rotation2, Vector2};

use super::render::ObjectVisibility;
use super::world::{VehicleView, World};
use slipstream_contract::msg::{GroundTruthObject, GroundTruthObjects};

/// Ground truth for the current state of `world`, around the first ego; `visibility` comes
/// from the frame rendered from this same state (vehicles beyond the draw distance have no
/// entry: no box, 0 visible).
pub fn ground_truth(world: &World, visibility: &[ObjectVisibility]) -> GroundTruthObjects {
    ground_truth_of(world, 0, visibility)
}

/// Ground truth around ego `k`: every other vehicle, the other egos among them.
pub(crate) fn ground_truth_of(world: &World, k: usize, visibility: &[ObjectVisibility]) -> GroundTruthObjects {
    let ego = world.ego_at(k);
    let objects = world.vehicles().iter().filter(|v| v.id != ego.id).map(|v| object(ego, v, visibility)).collect();
    GroundTruthObjects { step: world.step_count(), objects }
}

fn object(ego: &VehicleView, v: &VehicleView, visibility: &[ObjectVisibility]) -> GroundTruthObject {
    let ego_from_world = Rotation2::new(-ego.yaw_rad);
    let heading = Vector2::new(v.yaw_rad.cos(), v.yaw_rad.sin());
    let rear_face = v.rear_axle - heading * v.params.rear_overhang_m;
    let in_ego = ego_from_world * (rear_face - ego.rear_axle);
    // The rate of change of `in_ego`: of the two points' velocities (each body turns about
    // its centre of mass), and of the ego's axes turning with it (yaw rate w, -w x r). A
    // vehicle keeping its place ahead round a bend has none, as a sensor's range rate says,
    // although its velocity points another way than the ego's.
    let between = point_velocity(v, rear_face) - point_velocity(ego, ego.rear_axle);
    let w = ego.yaw_rate_radps;
    let relative_velocity = ego_from_world * between + Vector2::new(w * in_ego.y, -w * in_ego.x);
    let height = v.params.size_m[2];
    let vis = visibility.iter().find(|o| o.id == v.id);
    GroundTruthObject {
        id: v.id,
        class: v.class,
        size_m: v.params.size_m,
        lane: v.lane,
        position_in_world_m: [v.rear_axle.x, v.rear_axle.y, 0.0],
        yaw_in_world_rad: v.yaw_rad,
        velocity_in_world_mps: [v.velocity_mps.x, v.velocity_mps.y, 0.0],
        position_in_ego_m: [in_ego.x, in_ego.y, height / 2.0],
        yaw_in_ego_rad: wrap_angle(v.yaw_rad - ego.yaw_rad),
        velocity_in_ego_mps: [relative_velocity.x, relative_velocity.y, 0.0],
        bbox: vis.and_then(|o| o.bbox),
        visible_fraction: vis.map_or(0.0, |o| o.visible_fraction),
        brake_lights: v.brake_lights,
    }
}

/// The world velocity of a point fixed on a vehicle: its centre of mass's plus its turning
/// about it (the centre is half a wheelbase ahead of the rear axle).
fn point_velocity(v: &VehicleView, point: Vector2<f64>) -> Vector2<f64> {
    let heading = Vector2::new(v.yaw_rad.cos(), v.yaw_rad.sin());
    let arm = point - (v.rear_axle + heading * (v.params.wheelbase_m / 2.0));
    v.velocity_mps + Vector2::new(-arm.y, arm.x) * v.yaw_rate_radps
}

/// An angle in (-pi, pi].
fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let r = a.rem_euclid(tau);
    if r > std::f64::consts::PI {
        r - tau
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use crate::world::EgoInput;

    #[test]
    fn a_lead_in_lane_is_straight_ahead_at_its_gap_and_closing_speed() {
        let text = "{ name: 't', duration_s: 10, variation: { gap_m: 0, speed_mps: 0 }, ego: { lane: 1, speed_mps: 25 }, traffic: [ { lane: 1, gap_m: 30, speed_mps: 20 } ] }";
        let world = World::new(Scenario::parse(text, "t").unwrap(), 1, 100);
        let gt = ground_truth(&world, &[]);
        let o = &gt.objects[0];
        let ego = world.ego();
        let ego_front_from_rear_axle = ego.params.size_m[0] - ego.params.rear_overhang_m;
        assert!((o.position_in_ego_m[0] - (ego_front_from_rear_axle + 30.0)).abs() < 1e-3, "{o:?}");
        assert!(o.position_in_ego_m[1].abs() < 1e-3);
        assert!((o.velocity_in_ego_mps[0] + 5.0).abs() < 1e-3);
        assert_eq!((o.lane, o.bbox, o.visible_fraction), (1, None, 0.0));
        assert_eq!(wrap_angle(3.0 * std::f64::consts::PI), std::f64::consts::PI);
    }

    /// Round a bend the ego's axes turn: the velocity in them is the rate of change of the
    /// position in them (what a range rate measures), not the velocities' difference turned
    /// into them, which reads a lead at the ego's speed 40 m ahead on a 300 m radius as
    /// 0.2 m/s slower and made the ground-truth ACC's lead filter diverge when it braked.
    #[test]
    fn velocity_in_ego_is_the_rate_of_change_of_position_in_ego_round_a_bend() {
        let text = "{ name: 't', duration_s: 20, variation: { gap_m: 0, speed_mps: 0 }, \
            road: { curves: [ { start_m: 0, length_m: 3000, radius_m: 300 } ] }, \
            ego: { lane: 1, speed_mps: 22 }, \
            traffic: [ { lane: 1, gap_m: 40, speed_mps: 22 }, { lane: 2, gap_m: 20, speed_mps: 26 } ] }";
        let hz = 100;
        let mut world = World::new(Scenario::parse(text, "t").unwrap(), 1, hz);
        // Into the bend, every vehicle steady on its lane.
        for _ in 0..3 * hz {
            world.step(EgoInput::Cruise);
        }
        let before = ground_truth(&world, &[]);
        world.step(EgoInput::Cruise);
        let after = ground_truth(&world, &[]);
        assert!(world.ego().yaw_rate_radps.abs() > 0.05, "in the bend: {}", world.ego().yaw_rate_radps);
        let dt = 1.0 / hz as f64;
        for (a, b) in before.objects.iter().zip(&after.objects) {
            for axis in 0..2 {
                let rate = (b.position_in_ego_m[axis] - a.position_in_ego_m[axis]) / dt;
                let v = (a.velocity_in_ego_mps[axis] + b.velocity_in_ego_mps[axis]) / 2.0;
                assert!(
                    (rate - v).abs() < 0.02,
                    "vehicle {} axis {axis}: position changes at {rate:.3} m/s, velocity {v:.3}",
                    a.id
                );
            }
        }
    }
}
