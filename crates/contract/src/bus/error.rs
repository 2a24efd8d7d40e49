//! What can go wrong on the bus, said for a person.
//!
//! Zenoh's errors carry the source location inside the dependency (`... at
//! /root/.cargo/registry/.../close.rs:135.`): useful to Zenoh's developers, noise to a user, and
//! a path on the machine that built the binary. Every Zenoh error that reaches a message of
//! ours goes through [`zenoh_message`], which keeps what happened and drops where.

use crate::config::ConfigError;

/// What can go wrong on the bus. Decode errors are not here: they are counted per
/// subscription and logged, never returned to the node as a failure of the bus.
#[derive(Debug, thiserror::Error)]
pub enum BusError {
    /// Zenoh refused or failed an operation; `message` is its error without source locations.
    #[error("zenoh: {context}: {message}")]
    Zenoh { context: String, message: String },
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("invalid frame: {0}")]
    InvalidFrame(#[from] crate::msg::PixelError),
    #[error("the subscription to {0} is closed")]
    Closed(String),
}

/// Maps a Zenoh error to [`BusError::Zenoh`] with what was being done.
pub(crate) fn zerr(context: impl Into<String>) -> impl FnOnce(zenoh::Error) -> BusError {
    let context = context.into();
    move |source| BusError::Zenoh { context, message: zenoh_message(&source) }
}

/// A Zenoh error's text without the source locations Zenoh appends (` at FILE.rs:LINE.`).
pub fn zenoh_message(e: &dyn std::fmt::Display) -> String {
    without_source_locations(&e.to_string())
}

/// `text` with every ` at <file>.rs:<line>` (and its closing period) taken out.
pub fn without_source_locations(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find(" at ") {
        let after = &rest[i + " at ".len()..];
        let end = after.find(char::is_whitespace).unwrap_or(after.len());
        if is_source_location(&after[..end]) {
            out.push_str(&rest[..i]);
        } else {
            out.push_str(&rest[..i + " at ".len()]);
            out.push_str(&after[..end]);
        }
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

/// `/path/file.rs:123` or `src/x.rs:9.`: a file of Rust source and a line number.
fn is_source_location(token: &str) -> bool {
    let token = token.trim_end_matches('.');
    token.rsplit_once(':').is_some_and(|(file, line)| {
        file.ends_with(".rs") && !line.is_empty() && line.bytes().all(|b| b.is_ascii_digit())
    })
}

#[cfg(test)]
mod tests {
    use super::without_source_locations;

    #[test]
    fn zenoh_source_locations_are_dropped_and_the_rest_kept() {
        let raw = "close operation timed out! at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/zenoh-1.10.2/src/api/builders/close.rs:135.";
        assert_eq!(without_source_locations(raw), "close operation timed out!");
        let nested = "open failed at src/net/runtime/mod.rs:12. - Caused by refused at /x/y.rs:7.";
        assert_eq!(without_source_locations(nested), "open failed - Caused by refused");
        // " at " in ordinary text stays.
        let plain = "listener at tcp/127.0.0.1:7447 is taken, look at the log";
        assert_eq!(without_source_locations(plain), plain);
    }
}
