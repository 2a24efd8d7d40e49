//! slipstream-acc: adaptive cruise control as its own process. It reads vehicle/speed,
//! vehicle/state and the vehicles ahead (perception/objects, or the simulator's ground truth),
//! takes acc/command, and drives the ego through vehicle/control while reporting acc/status.
//!
//! - [`controller`]: the decisions, free of I/O, wiring its parts: [`ego`] (the ego's
//!   motion), [`objects`] (the vehicles ahead it is fed), [`lane`] (the lane ahead on the
//!   map), [`in_lane`] (a track's place in the lane as a probability), [`select`] (lead
//!   selection), [`lead_filter`] (the lead estimate), [`belief`] (what
//!   the lead plausibly does), [`threat`], [`decision`] (comfort braking or an emergency),
//!   [`command`] (the comfort command, jerk limit and release) and [`low_level`] (throttle
//!   and brake);
//! - [`node`]: the controller on the bus (lockstep answers, input health, watchdog);
//! - [`settings`]: config/acc.json5, with [`tuning`] (every behavioural number);
//! - [`args`]: slipstream-acc's command-line flags.
//!
//! It knows the vehicle it drives through the shared model ([`slipstream_model::vehicle`]) and the
//! simulator only through the bus: no simulator code is linked into these decisions, so the
//! same controller can drive another simulator or a car. Its scenario suite lives in the eval
//! layer (`slipstream eval acc`: crates/eval/src/acc.rs).
//!
//! The control law and its numbers: docs/control.md.

pub mod args;
mod belief;
mod command;
mod controller;
mod decision;
mod ego;
pub mod in_lane;
mod lane;
mod lead_filter;
mod low_level;
pub mod node;
mod objects;
mod select;
pub mod settings;
mod threat;
pub mod tuning;

pub use args::VehicleClass;
pub use controller::{Controller, Output};
pub use ego::{EgoNow, Pose};
pub use objects::{Object, PerceptionFrame};
pub use settings::{AccSettings, PerceptionSource};
pub use tuning::Share;

#[cfg(test)]
mod tests;
