//! slipstream-acc: adaptive cruise control as its own process. It reads vehicle/speed,
//! vehicle/state and the vehicles ahead (perception/objects, or the simulator's ground truth),
//! takes acc/command, and drives the ego through vehicle/control while reporting acc/status.
//!
//! - [`controller`]: the decisions, free of I/O (lead selection, spacing law, warning and
//!   emergency braking, stale-data fallback, low-level loop);
//! - [`node`]: the controller on the bus (lockstep answers, input health, watchdog);
//! - [`settings`]: config/acc.json5;
//! - [`args`]: slipstream-acc's command-line flags.
//!
//! It knows the vehicle it drives through the shared model ([`crate::vehicle`]) and the
//! simulator only through the bus: no simulator code is linked into these decisions, so the
//! same controller can drive another simulator or a car. Its scenario suite lives in the eval
//! layer (`slipstream eval acc`: src/eval/acc.rs).
//!
//! The control law and its numbers: docs/control.md.

pub mod args;
pub mod controller;
pub mod node;
pub mod settings;

pub use args::VehicleClass;
pub use controller::{Controller, EgoNow, Object, PerceptionFrame, Pose};
pub use settings::{AccSettings, PerceptionSource};

#[cfg(test)]
mod tests;
