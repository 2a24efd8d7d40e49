//! Seeing the loop while it runs, on one port: a page of its own for any browser (camera with
//! detections and ground-truth boxes, bird's-eye scene, the ACC's plots, every topic's figures,
//! latency per hop, nodes alive) and a Foxglove WebSocket server (the `foxglove` crate) with
//! the same drawings in Foxglove's schemas. Used by `slipstream view` and `slipstream up
//! --view` (docs/viewing.md), and as viewable copies in recordings (`record --viewable`,
//! [`copies`]).

pub(crate) mod birdseye;
pub(crate) mod board;
pub(crate) mod copies;
pub mod error;
pub(crate) mod front;
pub(crate) mod http;
pub(crate) mod live;
pub(crate) mod page;
pub(crate) mod scene;
pub(crate) mod timeline;

pub use copies::{Copies, ViewableCopy};
pub use error::{Error, Result};
pub use live::{LiveView, ViewOptions, ViewStats, DEFAULT_HOST, DEFAULT_PORT, DEFAULT_RATE_HZ};
pub use page::PageStats;
pub use scene::SceneContext;
pub use timeline::{Position, Timeline};
