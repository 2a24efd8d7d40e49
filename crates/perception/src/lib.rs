//! slipstream-detect: vehicles from camera frames.
//!
//! # Layout
//! - [`geometry`]: the calibrated camera: rays, the ground plane, distances.
//! - [`detector`]: one frame -> vehicles, classical computer vision (pixels + camera info only).
//! - [`tracker`]: detections joined into tracks; distance and relative speed by a Kalman filter.
//! - [`rig`]: the front and the narrow camera together: each vehicle once, tracked.
//! - [`settings`]: every number of the above, from config/detect.json5 (`--settings`).
//! - [`node`]: slipstream-detect on the bus (camera/front, camera/narrow -> perception/objects);
//!   [`args`]: its command line.
//!
//! It reads pixels and the camera's calibration only, never the simulator: scoring against the
//! simulator's ground truth is the eval layer's (`slipstream eval detect`: crates/eval/src/detect.rs).
//!
//! docs/perception.md describes the method, its limits and its measured scores.

pub mod args;
mod detector;
mod geometry;
pub mod node;
mod rig;
mod settings;
mod tracker;

pub use detector::{Detector, DetectorParams, FrameDetection};
pub use geometry::CameraModel;
pub use rig::CameraRig;
pub use settings::{DetectSettings, FusionParams};
pub use tracker::TrackerParams;
