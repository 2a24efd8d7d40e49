//! The vehicle model shared by the simulator and the controllers: a vehicle type's parameters
//! and the inverse longitudinal model (the throttle or brake that gives an acceleration).
//!
//! It sits below both: the simulator's forces (crates/sim/src/dynamics.rs) and the ACC's low-level
//! loop (crates/acc/src/low_level.rs) read the same numbers, and the ACC links none of the simulator.
//!
//! Longitudinally, per vehicle, the contract's model (slipstream_contract::longitudinal: what
//! sim/ego declares to a controller of any make, so its formulas live there):
//! - drive force = throttle * min(max_drive_force, max_power / speed), along the heading;
//! - resisting force = brake * mass * max_brake_decel + rolling_coeff * mass * g
//!   + 0.5 * air_density * drag_area * v^2, against the motion;
//! - throttle and brake act through a first-order lag of `actuator_lag_s` (engine torque
//!   build-up, brake pressure): the applied value moves toward the commanded one by
//!   1 - exp(-dt / lag) a step, so a step in the command reaches 63% after the lag.

use serde::{Deserialize, Serialize};

use slipstream_contract::longitudinal::Longitudinal;
use slipstream_contract::msg::{EgoInfo, ObjectClass};

/// The longitudinal formulas are the contract's (what sim/ego declares to any controller).
pub use slipstream_contract::longitudinal::{AIR_DENSITY_KGPM3, GRAVITY_MPS2};

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
    /// Time constant of the first-order lag between the commanded and the applied throttle
    /// and brake, seconds (powertrains and brakes: 0.2-0.5 s).
    pub actuator_lag_s: f64,
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
        actuator_lag_s: 0.3,
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
        actuator_lag_s: 0.35,
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
        // Air brakes and a heavier driveline.
        actuator_lag_s: 0.5,
    };

    /// A mid-size motorcycle with its rider: narrow (a third of a lane), light, quick to
    /// brake, and as tall as a car.
    pub const MOTORCYCLE: VehicleParams = VehicleParams {
        mass_kg: 300.0,
        size_m: [2.2, 0.8, 1.5],
        wheelbase_m: 1.45,
        rear_overhang_m: 0.35,
        max_power_w: 70_000.0,
        max_drive_force_n: 2_800.0,
        max_brake_decel_mps2: 9.0,
        drag_area_m2: 0.45,
        rolling_coeff: 0.015,
        max_steer_rad: 0.6,
        tyre_mu: 1.0,
        actuator_lag_s: 0.2,
    };

    pub fn of_class(class: ObjectClass) -> VehicleParams {
        match class {
            ObjectClass::Van => Self::VAN,
            ObjectClass::Truck => Self::TRUCK,
            ObjectClass::Motorcycle => Self::MOTORCYCLE,
            ObjectClass::Car | ObjectClass::Unknown => Self::CAR,
        }
    }

    /// Centre of the body box ahead of the rear axle (the centre of mass sits there too).
    pub fn center_ahead_of_rear_axle_m(&self) -> f64 {
        self.size_m[0] / 2.0 - self.rear_overhang_m
    }

    /// This vehicle's longitudinal model (the contract's formulas, these numbers).
    pub fn longitudinal(&self) -> Longitudinal {
        Longitudinal {
            mass_kg: self.mass_kg,
            max_power_w: self.max_power_w,
            max_drive_force_n: self.max_drive_force_n,
            max_brake_decel_mps2: self.max_brake_decel_mps2,
            drag_area_m2: self.drag_area_m2,
            rolling_coeff: self.rolling_coeff,
        }
    }

    /// What sim/ego announces of a `class` vehicle with these parameters and the driver's
    /// starting settings: the one place a vehicle's numbers become the contract's message.
    pub fn ego_info(&self, class: ObjectClass, set_speed_mps: f64, time_gap_s: Option<f64>) -> EgoInfo {
        EgoInfo {
            class,
            size_m: self.size_m,
            rear_overhang_m: self.rear_overhang_m,
            wheelbase_m: self.wheelbase_m,
            mass_kg: self.mass_kg,
            max_power_w: self.max_power_w,
            max_drive_force_n: self.max_drive_force_n,
            max_brake_decel_mps2: self.max_brake_decel_mps2,
            drag_area_m2: self.drag_area_m2,
            rolling_coeff: self.rolling_coeff,
            actuator_lag_s: self.actuator_lag_s,
            set_speed_mps,
            time_gap_s,
        }
    }

    /// Largest drive force at a forward speed.
    pub fn drive_force_limit_n(&self, forward_speed_mps: f64) -> f64 {
        self.longitudinal().drive_force_limit_n(forward_speed_mps)
    }

    /// Rolling and air resistance at a speed (brakes off).
    pub fn resistance_n(&self, speed_mps: f64) -> f64 {
        self.longitudinal().resistance_n(speed_mps)
    }
}

/// `applied` one step of `dt_s` later when `commanded` acts through a first-order lag of
/// `lag_s` (at once without lag): the one place the actuator lag is computed, for the
/// simulator's vehicles and for whoever models them.
pub fn lag_toward(applied: f64, commanded: f64, lag_s: f64, dt_s: f64) -> f64 {
    let share = if lag_s <= 0.0 { 1.0 } else { 1.0 - (-dt_s / lag_s).exp() };
    applied + (commanded - applied) * share
}

/// The inverse longitudinal model: throttle and brake (each 0..1, one of them 0) that give
/// `accel_mps2` at `speed_mps`, with the vehicle's own resistance, power and brake limits.
pub fn actuate_acceleration(params: &VehicleParams, speed_mps: f64, accel_mps2: f64) -> (f64, f64) {
    params.longitudinal().pedals_for(speed_mps, accel_mps2)
}
