//! The longitudinal vehicle model every ego declares on the bus (sim/ego's `EgoInfo` carries its
//! numbers): drive force, resistance, and its inverse, the throttle or brake that gives an
//! acceleration. It lives in the contract because a controller of any make turns its wanted
//! acceleration into pedals from what sim/ego says, and the simulator (through
//! slipstream-zenoh-model) drives with the same formulas: one place, so the two cannot drift.
//!
//! - drive force = throttle * min(max_drive_force, max_power / max(speed, 1 m/s));
//! - resistance = rolling_coeff * mass * g + 0.5 * air_density * drag_area * speed^2;
//! - brake force = brake * mass * max_brake_decel.

pub const GRAVITY_MPS2: f64 = 9.81;
pub const AIR_DENSITY_KGPM3: f64 = 1.2;

/// The numbers of one vehicle's longitudinal model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Longitudinal {
    pub mass_kg: f64,
    pub max_power_w: f64,
    /// Traction limit of the driven axle.
    pub max_drive_force_n: f64,
    /// Deceleration at full brake (brakes alone).
    pub max_brake_decel_mps2: f64,
    /// Drag coefficient times frontal area.
    pub drag_area_m2: f64,
    pub rolling_coeff: f64,
}

impl Longitudinal {
    /// Largest drive force at a forward speed.
    pub fn drive_force_limit_n(&self, forward_speed_mps: f64) -> f64 {
        self.max_drive_force_n.min(self.max_power_w / forward_speed_mps.max(1.0))
    }

    /// Rolling and air resistance at a speed (brakes off).
    pub fn resistance_n(&self, speed_mps: f64) -> f64 {
        self.rolling_coeff * self.mass_kg * GRAVITY_MPS2
            + 0.5 * AIR_DENSITY_KGPM3 * self.drag_area_m2 * speed_mps * speed_mps
    }

    /// The inverse model: throttle and brake (each 0..1, one of them 0) that give `accel_mps2`
    /// at `speed_mps`, within the vehicle's power, traction and brake limits.
    pub fn pedals_for(&self, speed_mps: f64, accel_mps2: f64) -> (f64, f64) {
        let needed = self.mass_kg * accel_mps2 + self.resistance_n(speed_mps);
        if needed >= 0.0 {
            ((needed / self.drive_force_limit_n(speed_mps)).min(1.0), 0.0)
        } else {
            (0.0, (-needed / (self.mass_kg * self.max_brake_decel_mps2)).min(1.0))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car() -> Longitudinal {
        // A mid-size car (the model crate's VehicleParams::CAR).
        Longitudinal {
            mass_kg: 1500.0,
            max_power_w: 110_000.0,
            max_drive_force_n: 6500.0,
            max_brake_decel_mps2: 9.0,
            drag_area_m2: 0.65,
            rolling_coeff: 0.012,
        }
    }

    #[test]
    fn throttle_is_power_limited_at_speed() {
        let p = car();
        assert_eq!(p.drive_force_limit_n(5.0), p.max_drive_force_n);
        assert!((p.drive_force_limit_n(40.0) - p.max_power_w / 40.0).abs() < 1e-9);
    }

    #[test]
    fn the_inverse_brakes_for_deceleration_and_drives_against_drag() {
        let (t, b) = car().pedals_for(30.0, 0.0);
        assert!(t > 0.0 && b == 0.0, "cruising needs throttle against drag");
        let (t, b) = car().pedals_for(30.0, -6.0);
        assert!(t == 0.0 && b > 0.5 && b < 0.7, "6 m/s2 needs about 2/3 brake: {b}");
        assert_eq!(car().pedals_for(10.0, 50.0), (1.0, 0.0), "beyond the limits: full throttle, no more");
    }
}
