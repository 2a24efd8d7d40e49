//! What the bus shows, read the same way by every tool that shows it: each key's figures as
//! they arrive ([`watch`]: what `top`, `up`'s report and the view's page count), the loop's
//! latency hop by hop from the stamps the messages carry ([`latency`]), and the per-node input
//! figures a run reports ([`NodeInput`]). It stands on the contract alone, below the view, the
//! recorder, the launcher and the evaluation, which all read these figures and none of which
//! the others may reach through it.

pub mod latency;
mod node_input;
pub mod watch;

pub use node_input::NodeInput;
