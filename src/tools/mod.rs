//! The `slipstream` command's tools that are not benchmarks.

pub mod children;
pub mod demo;
pub mod echo;
pub mod info;
pub mod latency;
pub mod top;
pub mod up;
