//! slipstream: a driving simulator, perception and cruise control as separate processes,
//! glued by Eclipse Zenoh with typed, timestamped, remappable topics.
//!
//! # Layout
//! Four layers; a module imports only from its own layer or the ones above it in this list.
//! The contract is a crate of its own (crates/contract, `slipstream_contract`): the compiler
//! keeps it from importing anything above. For the layers still in this crate,
//! tests/it/layering.rs reads the sources and fails on any other import.
//!
//! **Contract** (crates/contract, re-exported here under the same paths): what every process
//! agrees on.
//! - [`msg`]: one type per topic and its one wire encoding (postcard behind a version/kind
//!   preamble and a header with seq, simulation time and publish time); the clock rule
//!   [`msg::due`].
//! - [`topics`]: logical topics, their default keys, message types and QoS.
//! - [`qos`]: the QoS vocabulary of the config and its mapping onto Zenoh.
//! - [`config`]: config/slipstream.json5 (namespace, remapping, QoS) and the Zenoh connection
//!   flags every binary shares.
//! - [`bus`]: typed publishers and subscribers over a Zenoh session, latest-only delivery,
//!   per-subscription statistics, liveliness.
//!
//! **Domain**: the loop's parts; each stands alone on the contract.
//! - [`vehicle`]: the vehicle model shared by the simulator and the controllers.
//! - [`road`]: the road's geometry (lanes, curves, road coordinates), shared the same way.
//! - [`sim`]: slipstream-sim, the deterministic driving simulator.
//! - [`perception`]: slipstream-detect, vehicles from camera frames (never the simulator).
//! - [`acc`]: slipstream-acc, the adaptive cruise control (never the simulator).
//!
//! **Orchestration**: running and judging the loop.
//! - [`launch`]: the nodes as child processes: start, await on the bus, stop, logs.
//! - [`record`]: the bus into MCAP files, lossless and with every loss counted.
//! - [`eval`]: recording a run, metrics, plots, latency per hop; the detect and ACC suites.
//! - [`view`]: the live view, a Foxglove WebSocket server of camera, boxes, scene and series.
//! - [`ros2`]: the loop as ROS 2 sees it over rmw_zenoh's keys (CDR messages, graph tokens),
//!   and ROS 2 commands into the loop.
//!
//! **Tools**: what the `slipstream` command offers.
//! - [`tools`]: `up`, `record`, `play`, `view`, `top`, `echo`, `info`, `demo`, `router`.
//! - [`bench`]: `slipstream bench`, the bus against raw Zenoh, UDP and TCP in one run.
//! - [`cli`]: what every binary does first (Zenoh's runtime layout, logging).

// The layers below the tools are crates of their own, re-exported under their module names.
pub use slipstream_acc as acc;
pub use slipstream_bench as bench;
pub use slipstream_contract::{bus, config, msg, process, qos, topics};
pub use slipstream_model::{road, vehicle};
pub use slipstream_orchestration::{eval, launch, record, ros2, view};
pub use slipstream_perception as perception;
pub use slipstream_sim as sim;

pub mod cli;
pub mod tools;

pub use bus::{Bus, BusError};
pub use config::{ConnectArgs, TopicMap};
