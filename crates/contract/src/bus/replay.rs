//! How a replayed sample says that it is one.
//!
//! `slipstream play` (and the view's replay, and re-simulation) publish a recording's payloads
//! byte for byte, so the bytes alone cannot tell a replayed speed message from a live one. The
//! attachment can: a replayed sample names its recorded publisher with [`REPLAY_SUFFIX`]
//! (`sim@replay`). Every reader that must not take a replay for the live loop decides on that
//! name alone: an input keeps a live publisher over a replayed one ([`super::Following`]),
//! `top` and `up` count a replayed message but report no latency for its old stamp, `echo`
//! shows the name. The payload stays the recorded one, so decoders, recordings of a replay and
//! re-simulation comparisons are unchanged.

/// Appended to the recorded publisher's name in a replayed sample's attachment.
pub const REPLAY_SUFFIX: &str = "@replay";

/// The attachment a replay sends for a message `publisher` recorded: marked once, however
/// often a recording of a replay is replayed again.
pub fn replayed_name(publisher: &str) -> String {
    if is_replayed(Some(publisher)) {
        publisher.to_string()
    } else {
        format!("{publisher}{REPLAY_SUFFIX}")
    }
}

/// Whether a sample's attachment (its publisher's name) marks it as replayed.
pub fn is_replayed(source: Option<&str>) -> bool {
    source.is_some_and(|s| s.ends_with(REPLAY_SUFFIX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replayed_name_is_marked_once_and_recognised() {
        assert_eq!(replayed_name("sim"), "sim@replay");
        assert_eq!(replayed_name("sim@replay"), "sim@replay");
        assert!(is_replayed(Some("acc@replay")));
        assert!(!is_replayed(Some("acc")));
        assert!(!is_replayed(Some("replay")), "a node named replay is not a replay");
        assert!(!is_replayed(None));
    }
}
