//! The contract of a slipstream loop: what every process on the bus agrees on, and all a
//! node of the user's own needs (a controller, a listener) with nothing heavier than serde,
//! postcard and Zenoh.
//!
//! - [`msg`]: one type per topic and its one wire encoding (postcard behind a version/kind
//!   preamble and a header with seq, simulation time and publish time); the clock rule
//!   [`msg::due`].
//! - [`topics`]: logical topics, their default keys, message types and QoS.
//! - [`qos`]: the QoS vocabulary of the config and its mapping onto Zenoh.
//! - [`config`]: config/slipstream.json5 (namespace, remapping, QoS) and the Zenoh connection
//!   flags every binary shares.
//! - [`bus`]: typed publishers and subscribers over a Zenoh session, latest-only delivery,
//!   per-subscription statistics, liveliness.
//! - [`longitudinal`]: the vehicle model sim/ego declares (pedals for an acceleration).
//! - [`node`]: a node of the user's own as one function (a controller, a detector) and the
//!   shell every node's `main` shares (runtime, bus, stop signals).
//!
//! JPEG and PNG camera frames need the `images` feature (the `image` codec); raw and LZ4
//! frames do not.

pub mod msg;
pub mod qos;
pub mod topics;

pub mod bus;
pub mod config;
pub mod longitudinal;
pub mod node;
pub mod process;

pub use bus::{Bus, BusError};
pub use config::{ConnectArgs, TopicMap};
