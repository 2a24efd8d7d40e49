//! Running and judging the loop: the nodes as processes, the bus into files and back, the live
//! view, the loop as ROS 2 sees it, and the evaluation that turns runs into verdicts. It stands
//! on the domain crates (simulator, perception, ACC) and the contract; the tools and binaries
//! stand on it.
//!
//! Inside, one order holds: recordings may hold the view's Foxglove copies and ROS 2 messages,
//! evaluation runs the loop through launch and reads recordings; never the other way.
//! - [`launch`]: the nodes as child processes: start, await on the bus, stop, logs.
//! - [`view`]: the live view: a page of its own for any browser and a Foxglove WebSocket
//!   server, on one port (camera, boxes, bird's-eye scene, series, the bus's figures).
//! - [`watch`]: every key's figures as they arrive (what `top`, `up` and the page show).
//! - [`ros2`]: the loop as ROS 2 sees it over rmw_zenoh's keys (CDR messages, graph tokens),
//!   and ROS 2 commands into the loop.
//! - [`record`]: the bus into MCAP files, lossless and with every loss counted.
//! - [`eval`]: recording a run, metrics, plots, latency per hop; the detect and ACC suites.
//! - [`error`]: what can go wrong in any of them, one type for the crate.

pub mod error;
pub mod eval;
pub mod launch;
pub mod record;
pub mod ros2;
pub mod view;
pub mod watch;

pub use error::{Error, Result};
