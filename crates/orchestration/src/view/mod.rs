//! Seeing the loop while it runs: a Foxglove WebSocket server (the `foxglove` crate) serving
//! the camera with detections and ground-truth boxes, a 3D scene of the road and vehicles, and
//! the ACC's series. Used by `slipstream view` and `slipstream up --view` (docs/viewing.md),
//! and as viewable copies in recordings (`record --viewable`, [`copies`]).

pub(crate) mod copies;
pub(crate) mod live;
pub(crate) mod scene;

pub use copies::Copies;
pub use live::{LiveView, ViewOptions, ViewStats, DEFAULT_HOST, DEFAULT_PORT, DEFAULT_RATE_HZ};
