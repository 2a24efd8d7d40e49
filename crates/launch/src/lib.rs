//! The loop's nodes as child processes. One launch path for `slipstream up`,
//! `slipstream eval acc` and whatever runs the loop next: the same flags for every node, the
//! same wait for the nodes on the bus, the same way of stopping them, the same logs.
//!
//! # Layout
//! - [`child`]: one child process (found next to this binary, stopped with SIGINT then
//!   SIGKILL), free loopback ports.
//! - [`nodes`]: the loop (slipstream-acc, slipstream-detect with camera perception,
//!   slipstream-sim): [`LoopRun`] opens an observer session, starts the controllers, waits for
//!   their liveliness tokens, starts the simulator, watches for its end or a death, stops
//!   everything and reads the simulator's report.
//! - [`foreign`]: a detector or controller of the user's own (`--detector CMD`,
//!   `--controller CMD`) in the place of ours, its connection handed over in the environment.
//! - [`own_args`]: `--loop`, `--controller`, `--detector`, merged into the loop's own nodes.
//! - [`loop_file`]: `--loop FILE`, every role's node (ours or any command) and how it runs.
//! - [`ready`]: when a node counts as ready (its token, or a first sample).
//! - `router`: a `slipstream router` of a run's own on loopback ([`LocalRouter`]).
//! - [`supervise`]: a node process under its restart policy.
//! - [`external`]: a simulator started elsewhere (`up --sim external`), known by its messages:
//!   there once vehicle/speed arrives, over when it ends the scenario, runs the time asked
//!   for, or goes silent for [`external::SILENCE`] (5 s).
//!
//! # Timings (chosen here once, for every caller)
//! | constant | value | what for |
//! |---|---|---|
//! | [`NODE_START_TIMEOUT`] | 30 s | the controllers must be alive on the bus before the simulator starts (its first frame must find them listening) |
//! | [`NODE_POLL`] | 20 ms | how often the launcher looks at the bus and the processes while waiting |
//! | [`SETTLE`] | 200 ms | after the simulator ends, for its last messages to land (the others stop meanwhile) |
//! | [`STOP_GRACE`] | 5 s | SIGINT, then this long to exit, then SIGKILL |

use std::time::Duration;

pub mod child;
pub mod error;
pub(crate) mod external;
pub mod foreign;
pub(crate) mod hold;
pub mod loop_file;
pub(crate) mod namespace;
pub(crate) mod nodes;
pub(crate) mod own_args;
pub mod ready;
mod router;
pub mod supervise;

pub use child::{free_ports, sibling_binary, Child};
pub use error::{Error, Result};
pub use external::ExternalSim;
pub use foreign::{ForeignNode, OwnNodes};
pub use namespace::{nodes_alive_in, PLAYER};
pub use nodes::{
    last_words, log_of, refuse_in_lockstep, why_it_ended, AllNodes, ClockMode, EgoNodes, LinkKind, LoopRun, LoopSpec,
    Network, NodeEnd, Progress, ISOLATED_CFG,
};
pub use own_args::OwnNodeArgs;
pub use router::{listening_line, LocalRouter};

/// How long the controllers may take to appear on the bus.
pub(crate) const NODE_START_TIMEOUT: Duration = Duration::from_secs(30);
/// How often the launcher checks the bus and the processes.
pub const NODE_POLL: Duration = Duration::from_millis(20);
/// After the simulator ends: time for its last messages to reach the observer.
pub const SETTLE: Duration = Duration::from_millis(200);
/// SIGINT, then this long, then SIGKILL.
pub const STOP_GRACE: Duration = Duration::from_secs(5);
/// RUST_LOG for the nodes when the user set none: lifecycle at INFO, Zenoh's chatter off.
pub(crate) const DEFAULT_RUST_LOG: &str = "info,zenoh=warn,zenoh_ext=warn";
