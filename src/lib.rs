//! slipstream: a driving simulator, perception and cruise control as separate processes,
//! glued by Eclipse Zenoh with typed, timestamped, remappable topics.
//!
//! # Layout
//! - [`msg`]: one type per topic and its one wire encoding (postcard behind a version/kind
//!   preamble and a header with seq, simulation time and publish time).
//! - [`topics`]: logical topics, their default keys, message types and QoS.
//! - [`qos`]: the QoS vocabulary of the config and its mapping onto Zenoh.
//! - [`config`]: config/slipstream.json5 (namespace, remapping, QoS) and the Zenoh connection
//!   flags every binary shares.
//! - [`bus`]: typed publishers and subscribers over a Zenoh session, latest-only delivery,
//!   per-subscription statistics, liveliness.
//! - [`acc`]: slipstream-acc, the adaptive cruise control, and its scenario suite.
//! - [`bench`]: `slipstream bench`, the bus against raw Zenoh, UDP and TCP in one run.
//! - [`tools`]: `slipstream info` (and later `top`, `echo`).
//! - [`cli`]: tracing set-up shared by the binaries.

pub mod acc;
pub mod bench;
pub mod bus;
pub mod cli;
pub mod config;
pub mod msg;
pub mod perception;
pub mod qos;
pub mod sim;
pub mod tools;
pub mod topics;

pub use bus::{Bus, BusError};
pub use config::{ConnectArgs, TopicMap};
