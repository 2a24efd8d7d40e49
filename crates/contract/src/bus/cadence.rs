//! When the next message of a periodic stream is due, so that a reader thread can be awake
//! for it.
//!
//! A reader parked on a futex is woken by the receive thread; on a virtual machine whose other
//! core sleeps that wake-up is ~50-100 us (an inter-processor interrupt and the host
//! scheduling the core), which is most of what a shared-memory frame costs between Zenoh's
//! receive callback and the detector. A camera is periodic, so the wake-up can be paid
//! before the frame instead of after it: the reader sleeps until shortly before the frame is
//! due, then polls for it for a bounded window. A stream that is not periodic (lockstep and
//! fast runs, bursts, a stalled publisher) has no window and is read as before.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Streams faster than this are not polled for: their reader is rarely idle long enough
/// for the wake-up to matter, and a window each period would cost a large share of a core.
const MIN_PERIOD: Duration = Duration::from_millis(10);
/// The window opens this long before the frame is due, plus three times the arrival jitter:
/// a timed sleep here wakes ~100-200 us late (the timer slack and the wake-up itself).
const LEAD: Duration = Duration::from_micros(500);
/// ...and closes this long after it, plus three times the jitter (then the reader parks as
/// before).
const TRAIL: Duration = Duration::from_micros(1000);
/// The window never exceeds this share of the period (CPU spent polling, at most).
const MAX_WINDOW_SHARE: f64 = 0.05;
/// The period and the jitter are the median and the median deviation of this many latest
/// intervals: one late frame or a slow start does not move them.
const INTERVALS: usize = 8;
/// No window before this many intervals are known.
const MIN_INTERVALS: usize = 3;
/// Periodic while the jitter is at most this share of the period.
const MAX_JITTER_SHARE: f64 = 0.1;

/// Learns a stream's period from its arrivals.
#[derive(Debug, Clone, Default)]
pub(super) struct Cadence {
    last: Option<Instant>,
    /// The latest intervals, s (oldest first).
    intervals: VecDeque<f64>,
}

impl Cadence {
    /// Records an arrival at `at`.
    pub(super) fn arrived(&mut self, at: Instant) {
        if let Some(last) = self.last {
            if self.intervals.len() == INTERVALS {
                self.intervals.pop_front();
            }
            self.intervals.push_back(at.saturating_duration_since(last).as_secs_f64());
        }
        self.last = Some(at);
    }

    /// The window around the next arrival, `(opens, closes)`, while the stream is periodic.
    pub(super) fn window(&self) -> Option<(Instant, Instant)> {
        let last = self.last?;
        if self.intervals.len() < MIN_INTERVALS {
            return None;
        }
        let period_s = median(self.intervals.iter().copied());
        let jitter_s = median(self.intervals.iter().map(|i| (i - period_s).abs()));
        if period_s < MIN_PERIOD.as_secs_f64() || jitter_s > MAX_JITTER_SHARE * period_s {
            return None;
        }
        let half = MAX_WINDOW_SHARE * period_s / 2.0;
        let lead = (LEAD.as_secs_f64() + 3.0 * jitter_s).min(half);
        let trail = (TRAIL.as_secs_f64() + 3.0 * jitter_s).min(half);
        let due = last + Duration::from_secs_f64(period_s);
        Some((due - Duration::from_secs_f64(lead), due + Duration::from_secs_f64(trail)))
    }
}

/// The median of a few values (the upper one of an even count).
fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn after(start: Instant, ms: f64) -> Instant {
        start + Duration::from_secs_f64(ms / 1000.0)
    }

    fn fed(start: Instant, arrivals_ms: &[f64]) -> Cadence {
        let mut c = Cadence::default();
        for &ms in arrivals_ms {
            c.arrived(after(start, ms));
        }
        c
    }

    #[test]
    fn a_steady_camera_gets_a_window_around_its_next_frame() {
        let start = Instant::now();
        let c = fed(start, &[0.0, 50.0, 100.0, 150.0, 200.0]);
        let (opens, closes) = c.window().expect("a 20 Hz stream is periodic");
        let due = after(start, 250.0);
        assert!(opens < due && due < closes, "{opens:?} {due:?} {closes:?}");
        // Awake at most a twentieth of the period, around the frame.
        assert!(opens >= after(start, 248.749) && closes <= after(start, 251.251), "{:?}", closes - opens);
    }

    /// The first frames of a stream often come at odd intervals (the publisher matching, the
    /// first frame rendered late); one late frame happens any time. Neither moves the window
    /// off the steady rhythm.
    #[test]
    fn a_slow_start_or_one_late_frame_does_not_move_the_window() {
        let start = Instant::now();
        let c = fed(start, &[0.0, 40.0, 90.0, 140.0, 190.0, 243.0, 290.0]);
        let (opens, closes) = c.window().expect("periodic");
        let due = after(start, 340.0);
        assert!(opens < due && due < closes, "{:?} {:?}", due - opens, closes - due);
    }

    #[test]
    fn no_window_before_a_period_is_known() {
        let start = Instant::now();
        assert!(fed(start, &[]).window().is_none());
        assert!(fed(start, &[0.0]).window().is_none());
        assert!(fed(start, &[0.0, 50.0, 100.0]).window().is_none(), "two intervals");
    }

    #[test]
    fn fast_or_irregular_streams_get_no_window() {
        let start = Instant::now();
        // A lockstep run in fast mode: a frame every 3 ms.
        let fast: Vec<f64> = (0..20).map(|i| i as f64 * 3.0).collect();
        assert!(fed(start, &fast).window().is_none());
        // Bursts and gaps.
        let irregular = [0.0, 50.0, 51.0, 140.0, 150.0, 260.0, 262.0, 330.0, 400.0, 402.0];
        assert!(fed(start, &irregular).window().is_none());
    }

    #[test]
    fn jitter_widens_the_window_up_to_its_cap() {
        let start = Instant::now();
        let steady = fed(start, &[0.0, 50.0, 100.0, 150.0, 200.0]).window().unwrap();
        let jittery = fed(start, &[0.0, 51.0, 99.0, 151.0, 199.0, 251.0]).window().unwrap();
        assert!(jittery.1 - jittery.0 > steady.1 - steady.0);
        // Capped at a twentieth of the period (here ~50.6 ms).
        assert!(jittery.1 - jittery.0 <= Duration::from_micros(2_600), "{:?}", jittery.1 - jittery.0);
    }
}
