//! What can go wrong in judging runs: the suites' files, tables and plots, a run that failed, and
//! what the launcher, the recorder and the view refused, said for a person: one error type for the
//! crate, so that a tool prints what failed with the cause under it and a caller can tell one
//! failure from another. The tools above add their context with anyhow; nothing in this crate does.

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
    /// A file was read but does not hold what it should (`is no simulator report`).
    #[error("{} {what}", path.display())]
    Json { path: PathBuf, what: &'static str, source: serde_json::Error },
    /// A recording that cannot serve what was asked of it, with the fix.
    #[error("{} {problem}", path.display())]
    Recording { path: PathBuf, problem: String },
    /// A table could not be written.
    #[error("write {}", path.display())]
    Csv { path: PathBuf, source: csv::Error },
    /// A plot could not be drawn or saved.
    #[error("draw {}: {message}", path.display())]
    Plot { path: PathBuf, message: String },
    /// Zenoh refused an operation; `message` is its error without source locations.
    #[error("{context}: {message}")]
    Zenoh { context: String, message: String },
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A command-line value the command cannot run with.
    #[error("{flag} {rule}")]
    Flag { flag: String, rule: String },
    /// A loop that cannot run as asked (faults it cannot honour, a namespace in use), with the
    /// fix.
    #[error("{0}")]
    Refused(String),
    /// A node of the loop did not start, ended early or stopped answering.
    #[error("{node} {problem}")]
    Node { node: String, problem: String },
    /// The operating system refused what a run needs (a process, a thread, a port).
    #[error("{what}")]
    System { what: String, source: std::io::Error },
    /// One run of a suite failed; `run` names it and where its node logs are.
    #[error("{run} (node logs in {})", logs.display())]
    Run { run: String, logs: PathBuf, source: Box<Error> },
    /// A run's task ended without a result.
    #[error("a run's task failed")]
    Task(#[from] tokio::task::JoinError),
    /// A run ended without what judging it needs (too few states recorded).
    #[error("{0}")]
    Unjudged(String),
    /// Something slipstream made is not what it should be (a generated scenario that does not
    /// parse): a defect to report, with what was made.
    #[error("{0} (a bug of slipstream: please report it)")]
    Bug(String),
    /// A thread of the run ended by a panic (a defect: its message went to stderr).
    #[error("{0} panicked")]
    Panicked(&'static str),
    /// The work was asked to stop (a signal) before it was done.
    #[error("stopped before the end")]
    Interrupted,
    #[error(transparent)]
    Launch(#[from] slipstream_launch::Error),
    #[error(transparent)]
    Record(#[from] slipstream_record::Error),
    #[error(transparent)]
    View(#[from] slipstream_view::Error),
    #[error(transparent)]
    Ros2(#[from] slipstream_ros2::Error),
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

    /// A node's failure.
    pub(crate) fn node(node: impl Into<String>, problem: impl Into<String>) -> Error {
        Error::Node { node: node.into(), problem: problem.into() }
    }

    /// Maps a plotting error on `path` to [`Error::Plot`].
    pub(crate) fn plot<E: std::fmt::Display>(path: &Path) -> impl FnOnce(E) -> Error + '_ {
        move |e| Error::Plot { path: path.to_path_buf(), message: e.to_string() }
    }

    /// The error and every cause under it, on one line: what a report keeps of a failed run.
    pub fn chain(&self) -> String {
        let mut out = self.to_string();
        let mut cause = std::error::Error::source(self);
        while let Some(c) = cause {
            out.push_str(": ");
            out.push_str(&c.to_string());
            cause = c.source();
        }
        out
    }
}
