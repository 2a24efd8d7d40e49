//! Per-subscription statistics, updated on Zenoh's receive path from the header alone.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use serde::Serialize;

use crate::msg::Header;

/// How many latency samples are kept for percentiles.
const LATENCY_WINDOW: usize = 4096;
/// The window over which the rate and bandwidth are measured.
const RATE_WINDOW: Duration = Duration::from_secs(2);
/// At most one warning per subscription per this period for malformed payloads.
const LOG_PERIOD: Duration = Duration::from_secs(5);
/// Publishers whose sequence numbers one subscription follows apart (a live simulator and a
/// replay beside it, two controllers for one vehicle); past this, the longest silent one is
/// forgotten.
const SOURCES: usize = 8;

/// Counters and recent samples of one subscription. Shared between Zenoh's callback and
/// readers; a snapshot is cheap.
#[derive(Debug)]
pub struct TopicStats {
    name: String,
    inner: Mutex<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    received: u64,
    bytes: u64,
    decode_errors: u64,
    lost: u64,
    skipped: u64,
    restarts: u64,
    injected_dropped: u64,
    injected_delayed: u64,
    injected_duplicated: u64,
    /// The last sequence number per publisher (its attachment): gaps and restarts are counted
    /// within one publisher's sequence, never across two.
    last_seqs: Vec<(Option<String>, u64)>,
    last_arrival: Option<Instant>,
    latencies_ns: VecDeque<i64>,
    arrivals: VecDeque<(Instant, usize)>,
    last_log: Option<Instant>,
    unlogged_errors: u64,
}

/// A point-in-time view of a subscription's statistics.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize, PartialEq)]
#[serde(default)]
pub struct StatsSnapshot {
    /// The subscription's name (a topic, or a key); left out of JSON when empty (a row that
    /// names its key and topic itself: `top`).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub topic: String,
    pub received: u64,
    pub bytes: u64,
    pub rate_hz: f64,
    pub bandwidth_bps: f64,
    pub latency_p50_us: Option<f64>,
    pub latency_p99_us: Option<f64>,
    /// Messages missing from the sequence numbers (lost on the way).
    pub lost: u64,
    /// Messages that arrived but were overwritten or dropped by the subscriber's queue.
    pub skipped: u64,
    pub decode_errors: u64,
    /// Times the publisher's sequence went backwards (a publisher restarted).
    pub restarts: u64,
    /// Messages a fault profile (`--faults`) dropped on arrival: not in `lost`, which counts
    /// only what the network lost.
    pub injected_dropped: u64,
    /// Messages a fault profile held back (delay, jitter, a bandwidth queue).
    pub injected_delayed: u64,
    /// Messages a fault profile delivered twice.
    pub injected_duplicated: u64,
    /// Seconds since the last message, None before the first.
    pub age_s: Option<f64>,
}

impl TopicStats {
    pub fn new(name: impl Into<String>) -> Self {
        TopicStats { name: name.into(), inner: Mutex::new(Inner::default()) }
    }

    /// A well-formed header arrived from an unnamed publisher: count it, its latency and any
    /// sequence gap.
    pub fn on_message(&self, header: &Header, len: usize, now_wall_ns: u64) {
        self.on_message_from(None, header, len, now_wall_ns);
    }

    /// A well-formed header arrived from `source` (the sample's attachment): count it, any gap
    /// in that publisher's sequence, and its latency unless it is a replay's
    /// ([`super::is_replayed`]: its publish stamp is the recording's).
    pub fn on_message_from(&self, source: Option<&str>, header: &Header, len: usize, now_wall_ns: u64) {
        let latency = (!super::is_replayed(source)).then(|| now_wall_ns as i64 - header.stamp_pub_ns as i64);
        self.count(source, header, len, latency);
    }

    fn count(&self, source: Option<&str>, header: &Header, len: usize, latency_ns: Option<i64>) {
        let now = Instant::now();
        let mut s = self.inner.lock();
        s.received += 1;
        s.bytes += len as u64;
        match s.last_seqs.iter().position(|(from, _)| from.as_deref() == source) {
            Some(i) => {
                let last = s.last_seqs[i].1;
                if header.seq > last + 1 {
                    s.lost += header.seq - last - 1;
                } else if header.seq <= last {
                    s.restarts += 1;
                }
                // The most recent publisher last: the one forgotten first is the longest silent.
                let mut entry = s.last_seqs.remove(i);
                entry.1 = header.seq;
                s.last_seqs.push(entry);
            }
            None => {
                if s.last_seqs.len() == SOURCES {
                    s.last_seqs.remove(0);
                }
                s.last_seqs.push((source.map(str::to_string), header.seq));
            }
        }
        s.last_arrival = Some(now);
        if let Some(latency) = latency_ns {
            if s.latencies_ns.len() == LATENCY_WINDOW {
                s.latencies_ns.pop_front();
            }
            s.latencies_ns.push_back(latency);
        }
        s.arrivals.push_back((now, len));
        while s.arrivals.front().is_some_and(|(t, _)| now.duration_since(*t) > RATE_WINDOW) {
            s.arrivals.pop_front();
        }
    }

    /// A payload that did not decode. Logged at most once per LOG_PERIOD, with the count.
    pub fn on_decode_error(&self, error: &dyn std::fmt::Display) {
        let now = Instant::now();
        let mut s = self.inner.lock();
        s.decode_errors += 1;
        s.unlogged_errors += 1;
        if s.last_log.is_none_or(|t| now.duration_since(t) >= LOG_PERIOD) {
            tracing::warn!(topic = %self.name, dropped = s.unlogged_errors, total = s.decode_errors, "dropped malformed payload: {error}");
            s.last_log = Some(now);
            s.unlogged_errors = 0;
        }
    }

    pub(crate) fn on_injected_drop(&self) {
        self.inner.lock().injected_dropped += 1;
    }

    pub(crate) fn on_injected_delay(&self) {
        self.inner.lock().injected_delayed += 1;
    }

    pub(crate) fn on_injected_duplicate(&self) {
        self.inner.lock().injected_duplicated += 1;
    }

    /// A message that arrived but was dropped by the subscriber's queue.
    pub fn on_skipped(&self) {
        self.inner.lock().skipped += 1;
    }

    pub fn snapshot(&self) -> StatsSnapshot {
        let now = Instant::now();
        let s = self.inner.lock();
        let mut lat: Vec<i64> = s.latencies_ns.iter().copied().collect();
        lat.sort_unstable();
        let pct = |p: f64| -> Option<f64> {
            if lat.is_empty() {
                return None;
            }
            let i = ((lat.len() - 1) as f64 * p).round() as usize;
            Some(lat[i] as f64 / 1_000.0)
        };
        let in_window: Vec<_> = s.arrivals.iter().filter(|(t, _)| now.duration_since(*t) <= RATE_WINDOW).collect();
        let (rate_hz, bandwidth_bps) = match (in_window.first(), in_window.len()) {
            (Some((first, _)), n) if n >= 2 => {
                let span = now.duration_since(*first).as_secs_f64().max(1e-3);
                let bytes: usize = in_window.iter().map(|(_, b)| *b).sum();
                ((n as f64) / span, bytes as f64 * 8.0 / span)
            }
            _ => (0.0, 0.0),
        };
        StatsSnapshot {
            topic: self.name.clone(),
            received: s.received,
            bytes: s.bytes,
            rate_hz,
            bandwidth_bps,
            latency_p50_us: pct(0.50),
            latency_p99_us: pct(0.99),
            lost: s.lost,
            skipped: s.skipped,
            decode_errors: s.decode_errors,
            restarts: s.restarts,
            injected_dropped: s.injected_dropped,
            injected_delayed: s.injected_delayed,
            injected_duplicated: s.injected_duplicated,
            age_s: s.last_arrival.map(|t| now.duration_since(t).as_secs_f64()),
        }
    }

    /// All latency samples in the window, in ns (for benchmarks).
    pub fn latencies_ns(&self) -> Vec<i64> {
        self.inner.lock().latencies_ns.iter().copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn h(seq: u64) -> Header {
        Header { seq, stamp_sim_ns: 0, stamp_pub_ns: 1_000 }
    }

    #[test]
    fn a_replayed_message_is_counted_without_a_latency() {
        let s = TopicStats::new("t");
        s.on_message_from(Some("sim@replay"), &h(0), 10, 51_000);
        s.on_message_from(Some("sim@replay"), &h(2), 10, 51_000);
        let snap = s.snapshot();
        assert_eq!((snap.received, snap.lost), (2, 1));
        assert_eq!(snap.latency_p50_us, None, "a recorded stamp is no latency");
        s.on_message_from(Some("sim"), &h(3), 10, 51_000);
        assert_eq!(s.snapshot().latency_p50_us, Some(50.0));
    }

    #[test]
    fn two_publishers_on_one_subscription_are_each_counted_in_their_own_sequence() {
        let s = TopicStats::new("vehicle/speed");
        // A live simulator at 1000.. and a replay at 0.., interleaved: no gap, no restart.
        for k in 0..50 {
            s.on_message_from(Some("sim"), &h(1000 + k), 10, 51_000);
            s.on_message_from(Some("sim@replay"), &h(k), 10, 51_000);
        }
        let snap = s.snapshot();
        assert_eq!((snap.received, snap.lost, snap.restarts), (100, 0, 0));
        s.on_message_from(Some("sim"), &h(1052), 10, 51_000);
        assert_eq!(s.snapshot().lost, 2, "a gap in one publisher's own sequence");
    }

    #[test]
    fn gaps_count_as_lost_and_backwards_as_restart() {
        let s = TopicStats::new("t");
        for seq in [0, 1, 2, 5, 6, 0, 1] {
            s.on_message(&h(seq), 10, 51_000);
        }
        let snap = s.snapshot();
        assert_eq!(snap.received, 7);
        assert_eq!(snap.lost, 2);
        assert_eq!(snap.restarts, 1);
        assert_eq!(snap.bytes, 70);
        assert_eq!(snap.latency_p50_us, Some(50.0));
    }

    #[test]
    fn decode_errors_and_skips_are_counted() {
        let s = TopicStats::new("t");
        for _ in 0..3 {
            s.on_decode_error(&"bad");
        }
        s.on_skipped();
        let snap = s.snapshot();
        assert_eq!((snap.decode_errors, snap.skipped, snap.received), (3, 1, 0));
        assert_eq!(snap.latency_p50_us, None);
    }
}
