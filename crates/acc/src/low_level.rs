//! The low-level loop: from the target acceleration to throttle and brake, through the
//! vehicle model (`slipstream_model::vehicle::actuate_acceleration`) plus an integrator on the
//! acceleration error for what the model does not know (a slope, a heavier car).

use super::settings::AccSettings;
use slipstream_contract::msg::AccMode;
use slipstream_model::vehicle::{actuate_acceleration, VehicleParams};

/// The loop's memory.
#[derive(Debug, Clone, Default)]
pub(super) struct LowLevel {
    integral: f64,
    /// The throttle of the last step: while stale, never more than this.
    last_throttle: f64,
}

impl LowLevel {
    /// Throttle and brake for `accel` plus `lead` (the actuator lag's compensation) in `mode`,
    /// at speed `v` with `measured` the ego's measured acceleration.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn actuate(
        &mut self,
        s: &AccSettings,
        params: &VehicleParams,
        mode: AccMode,
        accel: f64,
        lead: f64,
        v: f64,
        measured: f64,
        dt: f64,
    ) -> (f32, f32) {
        let t = &s.tuning.low_level;
        match mode {
            AccMode::Off => {
                self.integral = 0.0;
                self.last_throttle = 0.0;
                return (0.0, 0.0);
            }
            AccMode::Emergency => {
                self.integral = 0.0;
                if accel <= -params.max_brake_decel_mps2 {
                    self.last_throttle = 0.0;
                    return (0.0, 1.0);
                }
            }
            _ => {
                if v > 1.0 && accel.abs() < s.limits.decel_mps2 {
                    self.integral = (self.integral + t.integral_gain_per_s.get() * (accel - measured) * dt)
                        .clamp(-t.integral_max_mps2.get(), t.integral_max_mps2.get());
                }
            }
        }
        let (mut throttle, brake) = actuate_acceleration(params, v, accel + lead + self.integral);
        if mode == AccMode::Stale {
            // Inputs too old: the throttle only goes down (it follows the eased target).
            throttle = throttle.min(self.last_throttle);
        }
        self.last_throttle = throttle;
        if v < t.standstill_mps.get() && accel <= 0.0 {
            self.last_throttle = 0.0;
            return (0.0, (brake as f32).max(t.hold_brake.get() as f32));
        }
        (throttle as f32, brake as f32)
    }
}
