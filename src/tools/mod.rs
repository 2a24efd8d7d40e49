//! The `slipstream` command's tools that are not benchmarks.

pub mod demo;
pub mod info;
