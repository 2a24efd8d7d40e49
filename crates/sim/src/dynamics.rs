//! The simulator's forward vehicle dynamics: the forces a vehicle's engine, brakes, air, tyres
//! and steering put on its body, from the shared parameters in [`slipstream_model::vehicle`]. Pure
//! functions on nalgebra types; crates/sim/src/physics.rs hands the result to rapier.
//!
//! The body moves in the road plane (x, y, yaw). Per step, longitudinal forces as documented in
//! [`slipstream_model::vehicle`], never reversing the motion; each axle's tyres resist sliding sideways
//! like a stiff damper, at most tyre_mu times the axle's load: the front axle's sideways
//! direction turns with the steering angle (steer * max_steer), which makes the body yaw. With
//! grip to spare this is the kinematic bicycle (yaw rate = v tan(delta) / wheelbase); past it
//! the vehicle slides.

use nalgebra::Vector2;

pub(crate) use slipstream_model::vehicle::VehicleParams;
use slipstream_model::vehicle::GRAVITY_MPS2;

/// What a driver (a controller or the traffic model) asks of a vehicle this step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Actuation {
    /// 0..1
    pub throttle: f64,
    /// 0..1
    pub brake: f64,
    /// -1 (full right) .. 1 (full left)
    pub steer: f64,
}

/// A vehicle's planar motion, at its centre of mass, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PlanarState {
    pub center: Vector2<f64>,
    pub yaw_rad: f64,
    pub velocity_mps: Vector2<f64>,
    pub yaw_rate_radps: f64,
}

impl PlanarState {
    pub(crate) fn heading(&self) -> Vector2<f64> {
        Vector2::new(self.yaw_rad.cos(), self.yaw_rad.sin())
    }

    /// Speed along the heading (negative when rolling backwards).
    pub(crate) fn forward_speed_mps(&self) -> f64 {
        self.velocity_mps.dot(&self.heading())
    }
}

/// Force at the centre of mass and torque about z, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PlanarWrench {
    pub force_n: Vector2<f64>,
    pub torque_nm: f64,
}

/// The forces on a vehicle for one step of `dt_s`.
pub(crate) fn forces(params: &VehicleParams, state: &PlanarState, input: &Actuation, dt_s: f64) -> PlanarWrench {
    let m = params.mass_kg;
    let heading = state.heading();
    let left = Vector2::new(-heading.y, heading.x);
    let v_fwd = state.forward_speed_mps();

    // Longitudinal: drive minus resistance, resistance never reversing the motion.
    let throttle = input.throttle.clamp(0.0, 1.0);
    let brake = input.brake.clamp(0.0, 1.0);
    let drive = throttle * params.drive_force_limit_n(v_fwd);
    let resist = brake * m * params.max_brake_decel_mps2 + params.resistance_n(v_fwd);
    let longitudinal = if v_fwd > 0.0 {
        drive - resist.min(drive + m * v_fwd / dt_s)
    } else if v_fwd < 0.0 {
        // Rolling back (after a collision): resistance pushes forward until it stops.
        drive + resist.min(m * -v_fwd / dt_s)
    } else {
        (drive - resist).max(0.0)
    };

    // Lateral: one stiff damper per axle (axles at +-wheelbase/2 from the centre of mass),
    // tuned to remove half the axle's sideways speed per step, capped by tyre grip.
    let half_base = params.wheelbase_m / 2.0;
    let steer_angle = input.steer.clamp(-1.0, 1.0) * params.max_steer_rad;
    let (sin_d, cos_d) = steer_angle.sin_cos();
    let front_left = left * cos_d - heading * sin_d;
    let axle_grip = params.tyre_mu * m * GRAVITY_MPS2 / 2.0;
    let damping = 0.5 * (m / 2.0) / dt_s;
    let axle = |offset: f64, sideways: Vector2<f64>| {
        let arm = heading * offset;
        let v_axle = state.velocity_mps + Vector2::new(-arm.y, arm.x) * state.yaw_rate_radps;
        let f = (-damping * v_axle.dot(&sideways)).clamp(-axle_grip, axle_grip);
        let force = sideways * f;
        (force, arm.x * force.y - arm.y * force.x)
    };
    let (f_front, t_front) = axle(half_base, front_left);
    let (f_rear, t_rear) = axle(-half_base, left);

    PlanarWrench { force_n: heading * longitudinal + f_front + f_rear, torque_nm: t_front + t_rear }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moving(speed: f64) -> PlanarState {
        PlanarState {
            center: Vector2::zeros(),
            yaw_rad: 0.0,
            velocity_mps: Vector2::new(speed, 0.0),
            yaw_rate_radps: 0.0,
        }
    }

    #[test]
    fn brakes_never_push_a_standing_car_backwards() {
        let w = forces(&VehicleParams::CAR, &moving(0.0), &Actuation { brake: 1.0, ..Default::default() }, 0.01);
        assert_eq!(w.force_n.x, 0.0);
        let w = forces(&VehicleParams::CAR, &moving(0.05), &Actuation { brake: 1.0, ..Default::default() }, 0.01);
        assert!(w.force_n.x < 0.0 && w.force_n.x * 0.01 / 1500.0 >= -0.05 - 1e-12, "overshoot: {}", w.force_n.x);
    }

    #[test]
    fn steering_left_turns_left() {
        let w = forces(&VehicleParams::CAR, &moving(20.0), &Actuation { steer: 0.2, ..Default::default() }, 0.01);
        assert!(w.torque_nm > 0.0 && w.force_n.y > 0.0, "{w:?}");
    }
}
