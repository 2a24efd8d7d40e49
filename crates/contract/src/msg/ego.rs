//! sim/ego: the vehicle a controller drives and the driver's settings when the scenario starts,
//! as the simulator announces them (latched). A controller of any make, in any language, drives
//! any scenario from what arrives on the bus, with no flag only our nodes understand.

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind, ObjectClass, Unsound};
use crate::longitudinal::Longitudinal;

/// The ego vehicle (the simulator's model of it) and its driver's starting settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EgoInfo {
    pub class: ObjectClass,
    /// Length, width, height of the body.
    pub size_m: [f64; 3],
    /// From the rear axle (the ego's origin in vehicle/state) to the rear bumper: the front
    /// bumper is `size_m[0] - rear_overhang_m` ahead of the origin.
    pub rear_overhang_m: f64,
    pub wheelbase_m: f64,
    pub mass_kg: f64,
    pub max_power_w: f64,
    /// Traction limit of the driven axle.
    pub max_drive_force_n: f64,
    /// Deceleration at full brake.
    pub max_brake_decel_mps2: f64,
    /// Drag coefficient times frontal area.
    pub drag_area_m2: f64,
    pub rolling_coeff: f64,
    /// First-order lag between the commanded and the applied throttle and brake.
    pub actuator_lag_s: f64,
    /// The cruise speed the driver sets at the start.
    pub set_speed_mps: f64,
    /// The time gap the driver sets at the start; None: the controller's own.
    pub time_gap_s: Option<f64>,
}

impl EgoInfo {
    /// From the rear axle to the front bumper.
    pub fn front_m(&self) -> f64 {
        self.size_m[0] - self.rear_overhang_m
    }

    /// The longitudinal model this vehicle declares: a controller's pedals for an acceleration.
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
}

impl Message for EgoInfo {
    const KIND: MessageKind = MessageKind::EgoInfo;
    fn check(&self) -> Result<(), Unsound> {
        let positive = [
            ("length", self.size_m[0]),
            ("width", self.size_m[1]),
            ("height", self.size_m[2]),
            ("wheelbase_m", self.wheelbase_m),
            ("mass_kg", self.mass_kg),
            ("max_power_w", self.max_power_w),
            ("max_drive_force_n", self.max_drive_force_n),
            ("max_brake_decel_mps2", self.max_brake_decel_mps2),
        ];
        if let Some((name, v)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return Err(Unsound(format!("{name} {v} must be a finite value > 0")));
        }
        let at_least_zero = [
            ("rear_overhang_m", self.rear_overhang_m),
            ("drag_area_m2", self.drag_area_m2),
            ("rolling_coeff", self.rolling_coeff),
            ("actuator_lag_s", self.actuator_lag_s),
            ("set_speed_mps", self.set_speed_mps),
        ];
        if let Some((name, v)) = at_least_zero.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            return Err(Unsound(format!("{name} {v} must be a finite value >= 0")));
        }
        if let Some(h) = self.time_gap_s.filter(|h| !(h.is_finite() && *h > 0.0)) {
            return Err(Unsound(format!("time_gap_s {h} must be a finite value > 0")));
        }
        Ok(())
    }
}

/// The example of docs/wire-format.md: the default car set to 25 m/s.
pub(super) fn example() -> EgoInfo {
    EgoInfo {
        class: ObjectClass::Car,
        size_m: [4.6, 1.85, 1.45],
        rear_overhang_m: 0.95,
        wheelbase_m: 2.7,
        mass_kg: 1500.0,
        max_power_w: 110_000.0,
        max_drive_force_n: 6500.0,
        max_brake_decel_mps2: 9.0,
        drag_area_m2: 0.65,
        rolling_coeff: 0.012,
        actuator_lag_s: 0.3,
        set_speed_mps: 25.0,
        time_gap_s: Some(1.8),
    }
}
