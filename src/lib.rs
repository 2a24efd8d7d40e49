//! slipstream: a driving simulator, perception and cruise control as separate processes,
//! glued by Eclipse Zenoh with typed, timestamped, remappable topics.
//!
//! # Layout
//! The root of a workspace whose crates are the layers (docs/architecture.md): the contract
//! (`slipstream_contract`: msg, topics, qos, config, bus, process), the shared model
//! (`slipstream_model`: vehicle, road), the domain (`slipstream_sim`, `slipstream_perception`,
//! `slipstream_acc`), the orchestration as six crates (`slipstream_observe`, `slipstream_ros2`,
//! `slipstream_view`, `slipstream_record`, `slipstream_launch`, `slipstream_eval`) and the bench (`slipstream_bench`). A lower crate cannot import a higher one:
//! it does not depend on it. This crate is the tools and the binaries:
//! - [`tools`]: `up`, `record`, `play`, `view`, `top`, `echo`, `info`, `demo`, `router`, ...
//! - [`cli`]: what every binary does first and last (logging, the error said for a person).
//!
//! Each lower crate is re-exported under its module name (`slipstream::sim`, `slipstream::msg`),
//! the paths the binaries and the integration tests use.

// The layers below the tools are crates of their own, re-exported under their module names.
pub use slipstream_acc as acc;
pub use slipstream_bench as bench;
pub use slipstream_contract::{bus, config, msg, node, process, qos, topics};
pub use slipstream_eval as eval;
pub use slipstream_launch as launch;
pub use slipstream_model::{road, vehicle};
pub use slipstream_observe as observe;
pub use slipstream_perception as perception;
pub use slipstream_record as record;
pub use slipstream_ros2 as ros2;
pub use slipstream_sim as sim;
pub use slipstream_view as view;

pub mod cli;
pub mod tools;

pub use bus::{Bus, BusError};
pub use config::{ConnectArgs, TopicMap};
