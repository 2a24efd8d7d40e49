//! The one place where the simulator meets rapier3d.
//!
//! rapier 0.36 speaks glam (f32); everything else in the simulator speaks nalgebra (f64). The
//! conversions live here and nowhere else. Each vehicle is a dynamic rigid body with a box
//! collider, free to move only in the road plane (x, y translation, yaw): the vehicle model
//! (crates/sim/src/dynamics.rs) supplies its forces as impulses each step; rapier integrates them and
//! resolves contacts between vehicles, which become collision events.

use std::collections::BTreeSet;

use nalgebra::Vector2;
use rapier3d::math::Vec3 as GVec3;
use rapier3d::prelude::*;

use super::dynamics::{PlanarState, PlanarWrench};
use slipstream_model::vehicle::VehicleParams;

fn to_glam(v: Vector2<f64>) -> GVec3 {
    GVec3::new(v.x as f32, v.y as f32, 0.0)
}

fn planar(v: GVec3) -> Vector2<f64> {
    Vector2::new(v.x as f64, v.y as f64)
}

/// A vehicle's body in the physics world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BodyId {
    body: RigidBodyHandle,
    collider: ColliderHandle,
}

/// The rigid-body world.
pub(crate) struct Physics {
    world: PhysicsWorld,
    /// Pairs of vehicle ids touching after the last step, to report only new contacts.
    touching: BTreeSet<(u32, u32)>,
}

impl Physics {
    pub(crate) fn new(dt_s: f64) -> Physics {
        let mut world = PhysicsWorld::new();
        // Motion is planar (z locked), so gravity acts only through the tyre loads the vehicle
        // model computes.
        world.gravity = GVec3::ZERO;
        world.integration_parameters.dt = dt_s as f32;
        Physics { world, touching: BTreeSet::new() }
    }

    /// Adds a vehicle with its rear axle at `rear_axle` (world, on the ground), heading `yaw_rad`
    /// and moving forward at `speed_mps`. `id` comes back in contacts.
    pub(crate) fn add_vehicle(
        &mut self,
        id: u32,
        params: &VehicleParams,
        rear_axle: Vector2<f64>,
        yaw_rad: f64,
        speed_mps: f64,
    ) -> BodyId {
        let heading = Vector2::new(yaw_rad.cos(), yaw_rad.sin());
        let body = RigidBodyBuilder::dynamic()
            .translation(to_glam(rear_axle))
            .rotation(GVec3::new(0.0, 0.0, yaw_rad as f32))
            .linvel(to_glam(heading * speed_mps))
            .locked_axes(
                LockedAxes::TRANSLATION_LOCKED_Z | LockedAxes::ROTATION_LOCKED_X | LockedAxes::ROTATION_LOCKED_Y,
            )
            .linear_damping(0.0)
            .angular_damping(0.0)
            .can_sleep(false)
            .user_data(id as u128)
            .build();
        let [length, width, height] = params.size_m;
        let collider = ColliderBuilder::cuboid((length / 2.0) as f32, (width / 2.0) as f32, (height / 2.0) as f32)
            .translation(GVec3::new(params.center_ahead_of_rear_axle_m() as f32, 0.0, (height / 2.0) as f32))
            .mass(params.mass_kg as f32)
            .friction(0.6)
            .restitution(0.1)
            .user_data(id as u128)
            .build();
        let (body, collider) = self.world.insert(body, collider);
        BodyId { body, collider }
    }

    /// Motion at the centre of mass.
    pub(crate) fn state(&self, id: BodyId) -> PlanarState {
        let b = &self.world.bodies[id.body];
        let x_axis = *b.rotation() * GVec3::X;
        PlanarState {
            center: planar(b.center_of_mass()),
            yaw_rad: (x_axis.y as f64).atan2(x_axis.x as f64),
            velocity_mps: planar(b.linvel()),
            yaw_rate_radps: b.angvel().z as f64,
        }
    }

    /// The body origin: rear-axle centre on the ground.
    pub(crate) fn rear_axle(&self, id: BodyId) -> Vector2<f64> {
        planar(self.world.bodies[id.body].translation())
    }

    /// Applies one step's worth (`dt_s`) of a wrench as impulses.
    pub(crate) fn apply(&mut self, id: BodyId, wrench: &PlanarWrench, dt_s: f64) {
        let b = &mut self.world.bodies[id.body];
        b.apply_impulse(to_glam(wrench.force_n * dt_s), true);
        b.apply_torque_impulse(GVec3::new(0.0, 0.0, (wrench.torque_nm * dt_s) as f32), true);
    }

    /// Advances the world one step and returns the pairs of vehicle ids (smaller first) that
    /// started touching in it.
    pub(crate) fn step(&mut self) -> Vec<(u32, u32)> {
        self.world.step();
        let mut now = BTreeSet::new();
        for pair in self.world.narrow_phase.contact_pairs() {
            if !pair.has_any_active_contact() {
                continue;
            }
            let id = |h: ColliderHandle| self.world.colliders.get(h).map(|c| c.user_data as u32);
            if let (Some(a), Some(b)) = (id(pair.collider1), id(pair.collider2)) {
                now.insert((a.min(b), a.max(b)));
            }
        }
        let started = now.difference(&self.touching).copied().collect();
        self.touching = now;
        started
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_body_keeps_its_pose_and_speed_without_forces() {
        let mut physics = Physics::new(0.01);
        let car = VehicleParams::CAR;
        let id = physics.add_vehicle(1, &car, Vector2::new(10.0, 2.0), 0.3, 5.0);
        let s0 = physics.state(id);
        assert!((s0.yaw_rad - 0.3).abs() < 1e-6);
        assert!((s0.forward_speed_mps() - 5.0).abs() < 1e-5);
        for _ in 0..100 {
            physics.step();
        }
        let moved = physics.rear_axle(id) - Vector2::new(10.0, 2.0);
        assert!((moved.norm() - 5.0).abs() < 1e-3, "moved {moved}");
    }

    #[test]
    fn two_bodies_driving_into_each_other_report_one_contact() {
        let mut physics = Physics::new(0.01);
        let car = VehicleParams::CAR;
        physics.add_vehicle(1, &car, Vector2::new(0.0, 0.0), 0.0, 10.0);
        physics.add_vehicle(2, &car, Vector2::new(8.0, 0.0), 0.0, 0.0);
        let mut contacts = Vec::new();
        for _ in 0..100 {
            contacts.extend(physics.step());
        }
        assert_eq!(contacts.first(), Some(&(1, 2)), "contacts {contacts:?}");
    }
}
