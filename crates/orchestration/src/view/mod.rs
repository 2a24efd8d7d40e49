//! Seeing the loop while it runs: a Foxglove WebSocket server (the `foxglove` crate) serving
//! the camera with detections and ground-truth boxes, a 3D scene of the road and vehicles, and
//! the ACC's series. Used by `slipstream view` and `slipstream up --view` (docs/viewing.md),
//! and as viewable copies in recordings (`record --viewable`, [`copies`]).

pub mod copies;
pub mod live;
pub mod scene;

pub use live::{LiveView, ViewOptions, ViewStats};
