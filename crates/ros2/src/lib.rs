//! ROS 2 sees the loop: the loop's topics as ROS 2 messages on rmw_zenoh's keys, with the
//! liveliness tokens that put them in the ROS graph, and a ROS 2 controller's commands into
//! the loop, over the same Zenoh network and with nothing to install on the ROS side but
//! rmw_zenoh (docs/ros2.md).
//!
//! # Layout
//! - [`catalog`], [`schema`]: the message definitions; DDS names, RIHS01 hashes, `ros2msg` text.
//! - [`messages`]: the messages as serde structs in CDR layout.
//! - [`convert`]: the loop's messages as ROS messages (frames, stamps in simulation time).
//! - [`graph`]: rmw_zenoh's data keys, liveliness tokens, QoS and attachment.
//! - [`mapping`]: the `ros2` block of config/slipstream.json5 (routes, names, types, QoS).
//! - [`translate`]: one bus payload into one route's CDR (live, recorded or converted alike).
//! - [`node`], [`outlet`], [`bag`]: where CDR goes: a ROS node's publishers, or a `ros2`-profile
//!   MCAP file.
//! - [`outbox`], [`bridge`]: the bus to an outlet, never holding up the bus.
//! - [`command`], [`inbound`]: ROS 2 commands into vehicle/control, checked and watched;
//!   [`lockstep`]: which step a command answers in a lockstep run; [`status`]: acc/status on
//!   the ROS controller's behalf, for the judge.
//! - [`face`]: the node, its publishers and its commands together (`slipstream ros2`).

pub mod bag;
pub(crate) mod bridge;
pub(crate) mod catalog;
pub(crate) mod command;
pub(crate) mod convert;
pub mod error;
pub(crate) mod face;
pub mod graph;
pub(crate) mod inbound;
pub(crate) mod lockstep;
pub mod mapping;
pub mod message_error;
pub(crate) mod messages;
pub(crate) mod node;
pub(crate) mod outbox;
pub(crate) mod outlet;
pub mod schema;
pub(crate) mod status;
pub mod translate;

pub use bag::Bag;
pub use bridge::{Bridge, RouteStats};
pub use command::CommandStats;
pub use error::{Error, Result};
pub use face::{FaceStats, RosFace};
pub use mapping::{Ros2Config, Route};
pub use message_error::Ros2Error;
pub use outlet::Outlet;
pub use schema::Distro;
