//! A node of the user's own in a few lines, on the contract alone: a controller is one function
//! (the ego, what is ahead, the driver's settings -> an acceleration) and the [`controller`]
//! module keeps the rest of docs/node-contract.md around it: lockstep answers naming their
//! step, stamps copied, objects read newest-first, the frame's objects awaited, acc/status for
//! the judge, the liveliness token once it listens; a detector is one function (a frame ->
//! detections) and [`detector`] keeps its side. [`serve`] is the shell every node's `main`
//! shares, slipstream-sim, slipstream-detect and slipstream-acc included: Zenoh's thread
//! layout, a runtime, the bus opened under the node's name, the stop signals, the bus left.
//! The Python package's `slipstream_client.controller` and `.detector` are the same design in
//! Python.

mod args;
pub mod controller;
mod controller_inputs;
pub mod detector;
mod failure;
mod law;
pub mod reader_thread;
mod shell;

pub use args::{ClockArg, NodeArgs, PerceptionArg};
pub use failure::Failure;
pub use shell::{serve, Shutdown};
