//! The `slipstream` command's tools that are not benchmarks: `up` (the whole loop, through the
//! launch and eval layers), `top`, `echo`, `info`, `demo`, `router`.

pub mod demo;
pub mod echo;
pub mod info;
pub mod router;
pub mod top;
pub mod up;
