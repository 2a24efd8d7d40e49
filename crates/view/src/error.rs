//! What can go wrong in the live view: its server, its Foxglove channels, its port, said for a person: one error type for the crate, so that a
//! tool prints what failed with the cause under it and a caller can tell one failure from
//! another. The tools above add their context with anyhow; nothing in this crate does.

use std::path::{Path, PathBuf};
use slipstream_contract::bus::{BusError, zenoh_message};
use slipstream_contract::config::ConfigError;

/// The crate's result.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What can go wrong here.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file or directory could not be opened, read, written or created.
    #[error("{action} {}", path.display())]
    File { action: &'static str, path: PathBuf, source: std::io::Error },
    /// Zenoh refused an operation; `message` is its error without source locations.
    #[error("{context}: {message}")]
    Zenoh { context: String, message: String },
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
    /// Maps an I/O error on `path` to [`Error::File`] (`action`: "create", "read", ...).
    pub(crate) fn file<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> Error + 'a {
        move |source| Error::File { action, path: path.to_path_buf(), source }
    }

    /// Maps a Zenoh error to [`Error::Zenoh`] with what was being done.
    pub(crate) fn zenoh<E: std::fmt::Display>(context: impl Into<String>) -> impl FnOnce(E) -> Error {
        let context = context.into();
        move |e| Error::Zenoh { context, message: zenoh_message(&e) }
    }

    /// A command-line value the command cannot run with.
    pub(crate) fn flag(flag: impl Into<String>, rule: impl Into<String>) -> Error {
        Error::Flag { flag: flag.into(), rule: rule.into() }
    }

    /// The OS refused `what`.
    pub(crate) fn system(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> Error {
        let what = what.into();
        move |source| Error::System { what, source }
    }
}
