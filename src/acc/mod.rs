//! slipstream-acc: adaptive cruise control as its own process. It reads vehicle/speed,
//! vehicle/state and the vehicles ahead (perception/objects, or the simulator's ground truth),
//! takes acc/command, and drives the ego through vehicle/control while reporting acc/status.
//!
//! - [`controller`]: the decisions, free of I/O (lead selection, spacing law, warning and
//!   emergency braking, stale-data fallback, low-level loop);
//! - [`node`]: the controller on the bus (lockstep answers, input health, watchdog);
//! - [`settings`]: config/acc.json5;
//! - [`eval`]: `slipstream eval acc`, the scenario suite with the simulator, detector and ACC
//!   as separate processes, its figures and plots; [`offline`] runs the same loop in one
//!   process without the bus, for tests.
//!
//! The control law and its numbers: docs/control.md.

pub mod args;
pub mod controller;
pub mod eval;
pub mod node;
pub mod offline;
pub mod settings;
pub mod suite;

pub use controller::{Controller, EgoNow, Object, PerceptionFrame};
pub use settings::{AccSettings, PerceptionSource};

#[cfg(test)]
mod tests;
