//! What can go wrong in the ROS 2 face's operations: its files and bags, Zenoh, its threads, and
//! the messages' own errors ([`crate::message_error::Ros2Error`]), said for a person: one error
//! type for the crate, so that a tool prints what failed with the cause under it and a caller can
//! tell one failure from another. The tools above add their context with anyhow; nothing in this
//! crate does.

use slipstream_contract::bus::{zenoh_message, BusError};
use slipstream_contract::config::ConfigError;
use std::path::{Path, PathBuf};

/// The crate's result.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What can go wrong here.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file or directory could not be opened, read, written or created.
    #[error("{action} {}", path.display())]
    File { action: &'static str, path: PathBuf, source: std::io::Error },
    /// A recording that cannot serve what was asked of it, with the fix.
    #[error("{} {problem}", path.display())]
    Recording { path: PathBuf, problem: String },
    /// An MCAP file could not be started, written, finished or read.
    #[error("{action} {}", path.display())]
    Mcap { action: &'static str, path: PathBuf, source: mcap::McapError },
    /// Zenoh refused an operation; `message` is its error without source locations.
    #[error("{context}: {message}")]
    Zenoh { context: String, message: String },
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The operating system refused what a run needs (a process, a thread, a port).
    #[error("{what}")]
    System { what: String, source: std::io::Error },
    /// A thread of the run ended by a panic (a defect: its message went to stderr).
    #[error("{0} panicked")]
    Panicked(&'static str),
    #[error(transparent)]
    Ros2(#[from] crate::message_error::Ros2Error),
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

    /// Maps an MCAP error on `path` to [`Error::Mcap`].
    pub(crate) fn mcap<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(mcap::McapError) -> Error + 'a {
        move |source| Error::Mcap { action, path: path.to_path_buf(), source }
    }

    /// The OS refused `what`.
    pub(crate) fn system(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> Error {
        let what = what.into();
        move |source| Error::System { what, source }
    }
}
