//! Which publisher an input follows.
//!
//! Every slipstream node names itself in its samples' attachment. A node's input follows the
//! first named publisher it hears: samples from any other publisher, or unnamed ones (a tool,
//! a flood of malformed payloads that happen to decode), are counted and not used: one input,
//! one source of truth. This is no security (anyone can put a name in an attachment: that is
//! what access control is for, docs/deployment.md); it keeps stray traffic on a key from
//! steering the loop.
//!
//! A replayed publisher (its name marked by [`super::replay`]) is followed only while no live
//! one is: a live publisher takes the input over from a replay at once, and a replay never
//! takes it over from a live one, however long the live one is silent. So a `slipstream play`
//! beside a running loop cannot steer it, and a loop started beside a replay drives itself.

use std::time::{Duration, Instant};

use super::replay::is_replayed;

/// How long the followed publisher may be silent before the next named one is followed (a
/// simulator restarted under another name).
pub const FOLLOW_SWITCH_AFTER: Duration = Duration::from_secs(2);
/// At most one log line per input per this period.
const LOG_EVERY: Duration = Duration::from_secs(5);

/// The publisher one input follows. Until a named publisher is heard, every sample is used (a
/// client that names nobody).
#[derive(Debug)]
pub struct Following {
    input: &'static str,
    /// Silence after which the next named publisher is followed; None: never (commands).
    switch_after: Option<Duration>,
    name: Option<String>,
    last_seen: Option<Instant>,
    rejected: u64,
    last_log: Option<Instant>,
}

impl Following {
    pub fn new(input: &'static str) -> Self {
        Following {
            input,
            switch_after: Some(FOLLOW_SWITCH_AFTER),
            name: None,
            last_seen: None,
            rejected: 0,
            last_log: None,
        }
    }

    /// An input that keeps its first named publisher however long it is silent: commands
    /// (acc/command) come now and then, and a second operator must not take over between two.
    pub fn first_only(input: &'static str) -> Self {
        Following { switch_after: None, ..Following::new(input) }
    }

    /// Whether a sample from `source` (its attachment), arriving at `now`, is used.
    pub fn accept(&mut self, source: Option<&str>, now: Instant) -> bool {
        let silent = match self.switch_after {
            Some(after) => self.last_seen.is_none_or(|t| now.duration_since(t) > after),
            None => self.name.is_none(),
        };
        let ok = match (&self.name, source) {
            (Some(n), Some(s)) if n == s => true,
            (None, None) => true,
            (None, Some(s)) => {
                tracing::info!(input = self.input, publisher = s, "following this publisher");
                self.name = Some(s.to_string());
                true
            }
            (Some(n), Some(s)) if is_replayed(Some(n)) && !is_replayed(Some(s)) => {
                tracing::warn!(
                    input = self.input,
                    publisher = s,
                    replay = n.as_str(),
                    "a live publisher took this input over from a replay"
                );
                self.name = Some(s.to_string());
                true
            }
            (Some(n), Some(s)) if silent && (is_replayed(Some(n)) || !is_replayed(Some(s))) => {
                tracing::warn!(
                    input = self.input,
                    publisher = s,
                    "the followed publisher went silent: following this one"
                );
                self.name = Some(s.to_string());
                true
            }
            _ => false,
        };
        if ok {
            self.last_seen = Some(now);
            return true;
        }
        self.rejected += 1;
        if self.last_log.is_none_or(|t| now.duration_since(t) >= LOG_EVERY) {
            self.last_log = Some(now);
            tracing::warn!(
                input = self.input,
                from = source.unwrap_or("(unnamed)"),
                following = self.name.as_deref().unwrap_or("-"),
                not_used = self.rejected,
                "samples from another publisher than the one followed: not used"
            );
        }
        false
    }

    /// Samples not used so far.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    /// The publisher followed, once one named itself.
    pub fn name(&self) -> Option<&str> {
        self.name.as_deref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_follows_its_first_named_publisher_and_counts_the_others() {
        let mut f = Following::new("vehicle/speed");
        let t0 = Instant::now();
        assert!(f.accept(None, t0), "nobody named yet: used");
        assert!(f.accept(Some("sim"), t0), "the first named publisher is followed");
        assert_eq!(f.name(), Some("sim"));
        assert!(!f.accept(None, t0), "unnamed (a malformed payload from a tool): not used");
        assert!(!f.accept(Some("intruder"), t0 + Duration::from_millis(500)));
        assert!(f.accept(Some("sim"), t0 + Duration::from_secs(1)));
        assert_eq!(f.rejected(), 2);
        // Silent for longer than FOLLOW_SWITCH_AFTER: the next named one takes over.
        let later = t0 + Duration::from_secs(1) + FOLLOW_SWITCH_AFTER + Duration::from_millis(1);
        assert!(f.accept(Some("sim-2"), later));
        assert!(!f.accept(Some("sim"), later));
    }

    #[test]
    fn a_replay_never_takes_an_input_from_a_live_publisher_and_a_live_one_takes_it_from_a_replay() {
        let t0 = Instant::now();
        let mut live_first = Following::new("vehicle/speed");
        assert!(live_first.accept(Some("sim"), t0));
        assert!(!live_first.accept(Some("sim@replay"), t0), "a replay beside the live loop is not used");
        let long_after = t0 + FOLLOW_SWITCH_AFTER * 10;
        assert!(!live_first.accept(Some("sim@replay"), long_after), "not even while the live one is silent");
        assert_eq!(live_first.name(), Some("sim"));
        assert_eq!(live_first.rejected(), 2);

        let mut replay_first = Following::new("vehicle/speed");
        assert!(replay_first.accept(Some("sim@replay"), t0), "a replay alone drives (re-simulation)");
        assert!(replay_first.accept(Some("sim"), t0 + Duration::from_millis(10)), "the live one takes over at once");
        assert!(!replay_first.accept(Some("sim@replay"), t0 + Duration::from_millis(20)));
        assert_eq!(replay_first.name(), Some("sim"));
    }

    #[test]
    fn commands_keep_their_first_operator_however_long_it_is_silent() {
        let mut f = Following::first_only("acc/command");
        let t0 = Instant::now();
        assert!(f.accept(Some("operator"), t0));
        assert!(!f.accept(Some("stranger"), t0 + Duration::from_secs(60)));
        assert!(f.accept(Some("operator"), t0 + Duration::from_secs(61)));
        assert_eq!(f.rejected(), 1);
    }
}
