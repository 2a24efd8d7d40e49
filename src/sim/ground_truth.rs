//! The objects message: every other vehicle as the simulator knows it, matched to one camera
//! frame (same step, same simulation time) through the renderer's visibility report.

use nalgebra::{Rotation2, Vector2};

use super::render::ObjectVisibility;
use super::world::{VehicleView, World};
use crate::msg::{GroundTruthObject, GroundTruthObjects};

/// Ground truth for the current state of `world`; `visibility` comes from the frame rendered
/// from this same state (vehicles beyond the draw distance have no entry: no box, 0 visible).
pub fn ground_truth(world: &World, visibility: &[ObjectVisibility]) -> GroundTruthObjects {
    let ego = world.ego();
    let objects = world.vehicles().iter().filter(|v| v.id != ego.id).map(|v| object(ego, v, visibility)).collect();
    GroundTruthObjects { step: world.step_count(), objects }
}

fn object(ego: &VehicleView, v: &VehicleView, visibility: &[ObjectVisibility]) -> GroundTruthObject {
    let ego_from_world = Rotation2::new(-ego.yaw_rad);
    let heading = Vector2::new(v.yaw_rad.cos(), v.yaw_rad.sin());
    let rear_face = v.rear_axle - heading * v.params.rear_overhang_m;
    let in_ego = ego_from_world * (rear_face - ego.rear_axle);
    let relative_velocity = ego_from_world * (v.velocity_mps - ego.velocity_mps);
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
    use crate::sim::scenario::Scenario;

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
}
