//! What can go wrong in running the loop's nodes as processes: their binaries, logs, reports, the
//! namespace and the ports, said for a person: one error type for the crate, so that a tool prints
//! what failed with the cause under it and a caller can tell one failure from another. The tools
//! above add their context with anyhow; nothing in this crate does.

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
    /// A node binary is not beside this one.
    #[error("{name} not found next to {} (build every binary: cargo build --release)", beside.display())]
    NoBinary { name: String, beside: PathBuf },
    /// The operating system refused what a run needs (a process, a thread, a port).
    #[error("{what}")]
    System { what: String, source: std::io::Error },
    /// Something slipstream made is not what it should be (a generated scenario that does not
    /// parse): a defect to report, with what was made.
    #[error("{0} (a bug of slipstream: please report it)")]
    Bug(String),
    /// The work was asked to stop (a signal) before it was done.
    #[error("stopped before the end")]
    Interrupted,
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

    /// A node's failure.
    pub(crate) fn node(node: impl Into<String>, problem: impl Into<String>) -> Error {
        Error::Node { node: node.into(), problem: problem.into() }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_error_names_the_action_and_path_and_keeps_the_cause_below() {
        let e = Error::file("create", Path::new("/x/y"))(std::io::Error::from(std::io::ErrorKind::PermissionDenied));
        assert_eq!(e.to_string(), "create /x/y");
        let cause = std::error::Error::source(&e).expect("the I/O error is the cause");
        assert!(cause.to_string().to_lowercase().contains("permission"), "{cause}");
        assert!(e.chain().starts_with("create /x/y: "), "{}", e.chain());
    }

    #[test]
    fn a_zenoh_error_loses_its_source_location() {
        let e = Error::zenoh("declare a publisher on a/b")("key is bad at /root/.cargo/x/y.rs:12.");
        assert_eq!(e.to_string(), "declare a publisher on a/b: key is bad");
    }
}
