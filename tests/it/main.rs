//! slipstream's integration tests: one test crate, so the library and Zenoh are linked into
//! one test binary (not one per file). Each module is one area; process-level tests spawn the
//! real binaries (`CARGO_BIN_EXE_*`).
//!
//! Tests that run whole loops or realtime simulators take [`common::serial`], so that on two
//! cores they do not starve each other. No test asserts a wall-clock speed, rate or loss count:
//! those figures belong to `slipstream bench` and `slipstream eval`.

#[macro_use]
mod common;

mod acc;
mod bus;
mod cli;
mod config;
mod detect_node;
mod discovery;
mod faults;
mod layering;
mod platoon;
mod record;
mod sim_egos;
mod sim_node;
mod sim_world;
mod structure;
mod sweep;
mod tools;
mod wire;
