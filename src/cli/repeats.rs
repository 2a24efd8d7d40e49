//! The warnings and errors of the libraries we did not write, each kind at most once per
//! period. A library logs what a peer does wrong (the Foxglove server an error for every
//! malformed message a viewer sends), so a client sending garbage would write a line to our
//! stderr for every message it sends; a log written faster than it is read blocks the process
//! on its stderr (a terminal held, a pipe nobody reads), and a blocked worker stalls the
//! process's runtime. Our own code rate-limits where peers cause its logs; this does it for
//! the rest: the first line of a kind at once, then one per period, preceded by the count of
//! those left out since.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use tracing::{Event, Metadata};
use tracing_subscriber::layer::{Context, Filter};

/// A kind of line is shown at most once per this period.
pub(super) const REPEAT_LOG_EVERY: Duration = Duration::from_secs(10);
/// Kinds remembered; beyond it the memory starts over (a bound, whatever peers send).
const KINDS_REMEMBERED: usize = 1024;

/// Lets a library's WARN or ERROR line of a kind through at most once per
/// [`REPEAT_LOG_EVERY`]; our own lines (targets `slipstream*`) and everything below WARN pass.
#[derive(Default)]
pub(super) struct Repeats {
    seen: parking_lot::Mutex<HashMap<(&'static str, String), Seen>>,
}

/// When a kind was last shown and how many of it were left out since.
struct Seen {
    shown: Instant,
    left_out: u64,
}

/// What to do with a line.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Verdict {
    /// Show it; `left_out` lines like it were not shown since the last one.
    Show {
        left_out: u64,
    },
    LeaveOut,
}

impl Repeats {
    /// The verdict on a line of `target` saying `message` at `now`.
    pub(super) fn judge(&self, target: &'static str, message: &str, now: Instant) -> Verdict {
        let mut seen = self.seen.lock();
        if seen.len() >= KINDS_REMEMBERED {
            seen.clear();
        }
        match seen.get_mut(&(target, kind(message))) {
            Some(s) if now.duration_since(s.shown) < REPEAT_LOG_EVERY => {
                s.left_out += 1;
                Verdict::LeaveOut
            }
            Some(s) => {
                let left_out = std::mem::take(&mut s.left_out);
                s.shown = now;
                Verdict::Show { left_out }
            }
            None => {
                seen.insert((target, kind(message)), Seen { shown: now, left_out: 0 });
                Verdict::Show { left_out: 0 }
            }
        }
    }
}

/// A line's kind: its text up to the first `": "` (what failed, before the particulars),
/// without digits (a peer's address and port, a count), at most 80 characters.
/// "Invalid message from 127.0.0.1:51166: expected ident" is of the kind
/// "Invalid message from ...:".
pub(super) fn kind(message: &str) -> String {
    let head = message.split(": ").next().unwrap_or(message);
    head.chars().filter(|c| !c.is_ascii_digit()).take(80).collect()
}

fn is_library(meta: &Metadata<'_>) -> bool {
    !meta.target().starts_with("slipstream") && *meta.level() <= tracing::Level::WARN
}

impl<S> Filter<S> for Repeats {
    fn enabled(&self, _meta: &Metadata<'_>, _cx: &Context<'_, S>) -> bool {
        true
    }

    fn event_enabled(&self, event: &Event<'_>, _cx: &Context<'_, S>) -> bool {
        let meta = event.metadata();
        if !is_library(meta) {
            return true;
        }
        let mut m = super::Message(String::new());
        event.record(&mut m);
        match self.judge(meta.target(), &m.0, Instant::now()) {
            Verdict::LeaveOut => false,
            Verdict::Show { left_out: 0 } => true,
            Verdict::Show { left_out } => {
                let note = format!(
                    "{} more lines like the next one from {} were left out in the last {} s\n",
                    left_out,
                    meta.target(),
                    REPEAT_LOG_EVERY.as_secs()
                );
                let _ = crate::tools::status::write_above(note.as_bytes());
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kind_is_what_failed_without_the_peers_particulars() {
        assert_eq!(kind("Invalid message from 127.0.0.1:51166: expected ident at line 1"), "Invalid message from ...:");
        assert_eq!(kind("Invalid message from 10.0.0.7:4000: Unknown binary opcode 255"), "Invalid message from ...:");
        assert_ne!(kind("Unable to connect to tcp/10.0.0.1:7447"), kind("Invalid message from 10.0.0.1:7447"));
        assert_eq!(kind(&"x".repeat(500)).len(), 80);
    }

    #[test]
    fn repeats_of_a_kind_are_shown_once_per_period_with_the_count_left_out() {
        let r = Repeats::default();
        let t0 = Instant::now();
        let target = "foxglove::websocket::connected_client";
        assert_eq!(r.judge(target, "Invalid message from 127.0.0.1:1: a", t0), Verdict::Show { left_out: 0 });
        for port in 2..12 {
            let later = t0 + Duration::from_millis(port * 100);
            assert_eq!(r.judge(target, &format!("Invalid message from 127.0.0.1:{port}: b"), later), Verdict::LeaveOut);
        }
        // Another kind, or the same kind from another library, is shown at once.
        assert_eq!(r.judge(target, "Client disconnected: x", t0), Verdict::Show { left_out: 0 });
        assert_eq!(r.judge("zenoh::net", "Invalid message from 127.0.0.1:1: a", t0), Verdict::Show { left_out: 0 });
        let after = t0 + REPEAT_LOG_EVERY;
        assert_eq!(r.judge(target, "Invalid message from 127.0.0.1:99: c", after), Verdict::Show { left_out: 10 });
        assert_eq!(r.judge(target, "Invalid message from 127.0.0.1:99: c", after), Verdict::LeaveOut);
    }

    #[test]
    fn whatever_peers_send_the_memory_stays_bounded() {
        let r = Repeats::default();
        let t0 = Instant::now();
        for i in 0..(3 * KINDS_REMEMBERED) {
            // Letters only: digits do not make a kind (see `kind`).
            let novel: String = format!("{i:04}").bytes().map(|d| char::from(b'a' + (d - b'0'))).collect();
            r.judge("foxglove", &format!("kind {novel}: at {i}"), t0);
            assert!(r.seen.lock().len() <= KINDS_REMEMBERED);
        }
    }
}
