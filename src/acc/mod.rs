//! slipstream-acc: adaptive cruise control as its own process. It reads vehicle/speed,
//! vehicle/state and the vehicles ahead (perception/objects, or the simulator's ground truth),
//! takes acc/command, and drives the ego through vehicle/control while reporting acc/status.
//!
//! - [`controller`]: the decisions, free of I/O (lead selection, spacing law, warning and
//!   emergency braking, stale-data fallback, low-level loop), from its parts:
//!   [`ego`] (the ego's motion), [`objects`] (the vehicles ahead it is fed), [`lane`] (the
//!   lane ahead on the map), [`lead_filter`] (the lead estimate) and [`threat`];
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
pub mod ego;
mod lane;
mod lead_filter;
pub mod node;
pub mod objects;
pub mod settings;
pub mod threat;

pub use args::VehicleClass;
pub use controller::Controller;
pub use ego::{EgoNow, Pose};
pub use objects::{Object, PerceptionFrame};
pub use settings::{AccSettings, PerceptionSource};

#[cfg(test)]
mod tests;
