//! slipstream-detect: vehicles from camera frames.
//!
//! # Layout
//! - [`geometry`]: the calibrated camera: rays, the ground plane, distances.
//! - [`detector`]: one frame -> vehicles, classical computer vision (pixels + camera info only).
//! - [`eval`]: scores detections against the simulator's ground truth.
//!
//! docs/perception.md describes the method, its limits and its measured scores.

pub mod detector;
pub mod eval;
pub mod geometry;

pub use detector::{Detector, DetectorParams, FrameDetection};
pub use geometry::CameraModel;
