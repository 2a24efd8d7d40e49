//! What can go wrong in the live view: its server, its Foxglove channels, its port, said for a
//! person: one error type for the crate, so that a tool prints what failed with the cause under it
//! and a caller can tell one failure from another. The tools above add their context with anyhow;
//! nothing in this crate does.

use slipstream_contract::bus::BusError;
use slipstream_contract::config::ConfigError;

/// The crate's result.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What can go wrong here.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The live view's Foxglove server or one of its channels could not start.
    #[error("{what}")]
    Foxglove { what: String, source: foxglove::FoxgloveError },
    /// A command-line value the command cannot run with.
    #[error("{flag} {rule}")]
    Flag { flag: String, rule: String },
    /// The operating system refused what a run needs (a process, a thread, a port).
    #[error("{what}")]
    System { what: String, source: std::io::Error },
}

impl Error {
    /// A command-line value the command cannot run with.
    pub(crate) fn flag(flag: impl Into<String>, rule: impl Into<String>) -> Error {
        Error::Flag { flag: flag.into(), rule: rule.into() }
    }
}
