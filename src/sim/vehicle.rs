//! The vehicle model: the forces a vehicle's engine, brakes, air, tyres and steering put on
//! its body. Pure functions on nalgebra types; src/sim/physics.rs hands the result to rapier.
//!
//! The body moves in the road plane (x, y, yaw). Per step:
//! - drive force = throttle * min(max_drive_force, max_power / speed), along the heading;
//! - resisting force = brake * mass * max_brake_decel + rolling_coeff * mass * g
//!   + 0.5 * air_density * drag_area * v^2, against the motion, never reversing it;
//! - each axle's tyres resist sliding sideways like a stiff damper, at most tyre_mu times the
//!   axle's load: the front axle's sideways direction turns with the steering angle
//!   (steer * max_steer), which makes the body yaw. With grip to spare this is the kinematic
//!   bicycle (yaw rate = v tan(delta) / wheelbase); past it the vehicle slides.

use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::msg::ObjectClass;

pub const GRAVITY_MPS2: f64 = 9.81;
const AIR_DENSITY_KGPM3: f64 = 1.2;

/// The parameters of one vehicle type.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VehicleParams {
    pub mass_kg: f64,
    /// Length, width, height of the body.
    pub size_m: [f64; 3],
    pub wheelbase_m: f64,
    /// Distance from the rear axle to the rear bumper.
    pub rear_overhang_m: f64,
    pub max_power_w: f64,
    /// Traction limit of the driven axle.
    pub max_drive_force_n: f64,
    /// Deceleration at full brake (brakes alone).
    pub max_brake_decel_mps2: f64,
    /// Drag coefficient times frontal area.
    pub drag_area_m2: f64,
    pub rolling_coeff: f64,
    /// Front wheel angle at steer = 1.
    pub max_steer_rad: f64,
    pub tyre_mu: f64,
}

impl VehicleParams {
    /// A mid-size car: 0-100 km/h in about 8 s, top speed about 220 km/h.
    pub const CAR: VehicleParams = VehicleParams {
        mass_kg: 1500.0,
        size_m: [4.6, 1.85, 1.45],
        wheelbase_m: 2.7,
        rear_overhang_m: 0.95,
        max_power_w: 110_000.0,
        max_drive_force_n: 6_500.0,
        max_brake_decel_mps2: 9.0,
        drag_area_m2: 0.65,
        rolling_coeff: 0.012,
        max_steer_rad: 0.55,
        tyre_mu: 1.0,
    };
    pub const VAN: VehicleParams = VehicleParams {
        mass_kg: 2400.0,
        size_m: [5.3, 2.0, 2.3],
        wheelbase_m: 3.3,
        rear_overhang_m: 1.0,
        max_power_w: 120_000.0,
        max_drive_force_n: 9_000.0,
        max_brake_decel_mps2: 8.0,
        drag_area_m2: 1.3,
        rolling_coeff: 0.013,
        max_steer_rad: 0.5,
        tyre_mu: 0.95,
    };
    pub const TRUCK: VehicleParams = VehicleParams {
        mass_kg: 12_000.0,
        size_m: [9.5, 2.5, 3.4],
        wheelbase_m: 5.5,
        rear_overhang_m: 2.2,
        max_power_w: 240_000.0,
        max_drive_force_n: 40_000.0,
        max_brake_decel_mps2: 6.5,
        drag_area_m2: 5.0,
        rolling_coeff: 0.008,
        max_steer_rad: 0.45,
        tyre_mu: 0.8,
    };

    pub fn of_class(class: ObjectClass) -> VehicleParams {
        match class {
            ObjectClass::Van => Self::VAN,
            ObjectClass::Truck => Self::TRUCK,
            ObjectClass::Car | ObjectClass::Unknown => Self::CAR,
        }
    }

    /// Centre of the body box ahead of the rear axle (the centre of mass sits there too).
    pub fn center_ahead_of_rear_axle_m(&self) -> f64 {
        self.size_m[0] / 2.0 - self.rear_overhang_m
    }

    /// Largest drive force at a forward speed.
    pub fn drive_force_limit_n(&self, forward_speed_mps: f64) -> f64 {
        self.max_drive_force_n.min(self.max_power_w / forward_speed_mps.max(1.0))
    }

    /// Rolling and air resistance at a speed (brakes off).
    pub fn resistance_n(&self, speed_mps: f64) -> f64 {
        self.rolling_coeff * self.mass_kg * GRAVITY_MPS2
            + 0.5 * AIR_DENSITY_KGPM3 * self.drag_area_m2 * speed_mps * speed_mps
    }
}

/// What a driver (a controller or the traffic model) asks of a vehicle this step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Actuation {
    /// 0..1
    pub throttle: f64,
    /// 0..1
    pub brake: f64,
    /// -1 (full right) .. 1 (full left)
    pub steer: f64,
}

/// A vehicle's planar motion, at its centre of mass, in the world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarState {
    pub center: Vector2<f64>,
    pub yaw_rad: f64,
    pub velocity_mps: Vector2<f64>,
    pub yaw_rate_radps: f64,
}

impl PlanarState {
    pub fn heading(&self) -> Vector2<f64> {
        Vector2::new(self.yaw_rad.cos(), self.yaw_rad.sin())
    }

    /// Speed along the heading (negative when rolling backwards).
    pub fn forward_speed_mps(&self) -> f64 {
        self.velocity_mps.dot(&self.heading())
    }
}

/// Force at the centre of mass and torque about z, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarWrench {
    pub force_n: Vector2<f64>,
    pub torque_nm: f64,
}

/// The forces on a vehicle for one step of `dt_s`.
pub fn forces(params: &VehicleParams, state: &PlanarState, input: &Actuation, dt_s: f64) -> PlanarWrench {
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
    fn throttle_is_power_limited_at_speed() {
        let p = VehicleParams::CAR;
        assert_eq!(p.drive_force_limit_n(5.0), p.max_drive_force_n);
        assert!((p.drive_force_limit_n(40.0) - p.max_power_w / 40.0).abs() < 1e-9);
    }

    #[test]
    fn steering_left_turns_left() {
        let w = forces(&VehicleParams::CAR, &moving(20.0), &Actuation { steer: 0.2, ..Default::default() }, 0.01);
        assert!(w.torque_nm > 0.0 && w.force_n.y > 0.0, "{w:?}");
    }
}
