//! From the peers' reports to a row: each run's figures (latency percentiles, throughput), then
//! the medians over runs.

use serde::Serialize;

use super::cases::Case;
use super::cases::CaseId;
use super::spec::{CaseSpec, RecvReport, SendReport};

/// One measured path in one table, medians over runs.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// What code finds the row by.
    pub id: CaseId,
    /// The table's and the path's labels, for people.
    pub suite: String,
    pub path: String,
    pub runs: usize,
    pub sent: f64,
    pub received: f64,
    pub lost: f64,
    pub p50_us: Option<f64>,
    pub p99_us: Option<f64>,
    pub max_us: Option<f64>,
    pub frames_per_s: Option<f64>,
    pub mb_per_s: Option<f64>,
    pub shared_memory_frames: f64,
    pub background_frames_per_s: Option<f64>,
    /// Frames handed from Zenoh's receive callback to a reader: p50 of publish -> callback
    /// (the link) and of callback -> reader (the hand-off), us.
    pub link_p50_us: Option<f64>,
    pub handoff_p50_us: Option<f64>,
}

/// One-way latencies (ns) in an HDR histogram: any percentile to 3 significant digits (within
/// 0.1 %) whatever the spread, in memory that does not grow with the count. A latency under
/// 1 ns (a clock step between stamps) counts as 1 ns.
pub(super) struct Latencies(hdrhistogram::Histogram<u64>);

impl Latencies {
    /// Up to an hour, in ns.
    const HIGHEST_NS: u64 = 3_600_000_000_000;

    pub(super) fn of(ns: &[i64]) -> Latencies {
        // Bounds and precision are constants inside what the library accepts.
        let mut h = hdrhistogram::Histogram::new_with_bounds(1, Self::HIGHEST_NS, 3).expect("valid histogram bounds");
        for &v in ns {
            h.saturating_record(v.max(1) as u64);
        }
        Latencies(h)
    }

    /// The `q` quantile (0.5: the median), us; None without samples.
    pub(super) fn us(&self, q: f64) -> Option<f64> {
        (!self.0.is_empty()).then(|| self.0.value_at_quantile(q) as f64 / 1000.0)
    }

    /// The largest, us; None without samples.
    pub(super) fn max_us(&self) -> Option<f64> {
        (!self.0.is_empty()).then(|| self.0.max() as f64 / 1000.0)
    }
}

/// The median of the values present.
pub fn median(values: impl IntoIterator<Item = Option<f64>>) -> Option<f64> {
    let mut v: Vec<f64> = values.into_iter().flatten().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 })
}

/// One run's figures.
pub(super) struct RunFigures {
    pub sent: f64,
    pub received: f64,
    lost: f64,
    pub p50: Option<f64>,
    p99: Option<f64>,
    max: Option<f64>,
    fps: Option<f64>,
    mbps: Option<f64>,
    shm: f64,
    bg_fps: Option<f64>,
    link_p50: Option<f64>,
    handoff_p50: Option<f64>,
}

pub(super) fn figures(spec: &CaseSpec, s: &SendReport, r: &RecvReport) -> RunFigures {
    let lat = Latencies::of(&r.latencies_ns);
    let throughput = spec.rate_hz.is_none() && r.received >= 2 && r.span_s > 0.0;
    RunFigures {
        sent: s.sent as f64,
        received: r.received as f64,
        lost: s.sent.saturating_sub(r.received) as f64,
        p50: lat.us(0.5),
        p99: lat.us(0.99),
        max: lat.max_us(),
        fps: throughput.then(|| r.received as f64 / r.span_s),
        mbps: throughput.then(|| r.bytes as f64 / r.span_s / 1e6),
        shm: r.shared_memory as f64,
        bg_fps: spec.background.map(|_| r.background_received as f64 / s.elapsed_s.max(1e-3)),
        link_p50: hops(r).map(|(link, _)| link),
        handoff_p50: hops(r).map(|(_, handoff)| handoff),
    }
}

/// A reader's frames split in two hops, p50 of each (us): publish -> receive callback, and
/// callback -> reader. None unless every measured frame has its hand-off.
fn hops(r: &RecvReport) -> Option<(f64, f64)> {
    if r.handoff_ns.is_empty() || r.handoff_ns.len() != r.latencies_ns.len() {
        return None;
    }
    let link: Vec<i64> = r.latencies_ns.iter().zip(&r.handoff_ns).map(|(l, h)| l - h).collect();
    Some((Latencies::of(&link).us(0.5)?, Latencies::of(&r.handoff_ns).us(0.5)?))
}

/// A case's row: the medians of its runs.
pub(super) fn row(case: &Case, runs: &[RunFigures]) -> Row {
    let med = |f: &dyn Fn(&RunFigures) -> Option<f64>| median(runs.iter().map(f));
    Row {
        id: case.id.clone(),
        suite: case.id.table.label(),
        path: case.id.path.label(),
        runs: runs.len(),
        sent: med(&|r| Some(r.sent)).unwrap_or(0.0),
        received: med(&|r| Some(r.received)).unwrap_or(0.0),
        lost: med(&|r| Some(r.lost)).unwrap_or(0.0),
        p50_us: med(&|r| r.p50),
        p99_us: med(&|r| r.p99),
        max_us: med(&|r| r.max),
        frames_per_s: med(&|r| r.fps),
        mb_per_s: med(&|r| r.mbps),
        shared_memory_frames: med(&|r| Some(r.shm)).unwrap_or(0.0),
        background_frames_per_s: med(&|r| r.bg_fps),
        link_p50_us: med(&|r| r.link_p50),
        handoff_p50_us: med(&|r| r.handoff_p50),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_readers_frames_split_into_link_and_hand_off_per_frame() {
        let r = RecvReport {
            latencies_ns: vec![300_000, 400_000, 500_000],
            handoff_ns: vec![100_000, 50_000, 80_000],
            ..RecvReport::default()
        };
        // Per frame: link 200, 350, 420 us; hand-off 100, 50, 80 us; medians to 0.1 %.
        let (link, handoff) = hops(&r).unwrap();
        assert!((link / 350.0 - 1.0).abs() < 1e-3 && (handoff / 80.0 - 1.0).abs() < 1e-3, "{link} {handoff}");
        // A frame without its hand-off: no split rather than a wrong one.
        let partial = RecvReport { handoff_ns: vec![100_000], ..r };
        assert_eq!(hops(&partial), None);
    }

    #[test]
    fn latency_percentiles_hold_three_significant_digits_at_any_spread() {
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-3;
        // 1..=10,000 us, shuffled by a stride: the median is 5,000 us, p99 9,900 us.
        let ns: Vec<i64> = (0..10_000).map(|i| ((i * 7_919) % 10_000 + 1) * 1_000).collect();
        let lat = Latencies::of(&ns);
        let (p50, p99, max) = (lat.us(0.5).unwrap(), lat.us(0.99).unwrap(), lat.max_us().unwrap());
        assert!(close(p50, 5_000.0) && close(p99, 9_900.0) && close(max, 10_000.0), "{p50} {p99} {max}");
        // Tens of us and seconds in one run keep their precision.
        let wide = Latencies::of(&[20_000, 20_000, 20_000, 2_000_000_000]);
        assert!(close(wide.us(0.5).unwrap(), 20.0) && close(wide.max_us().unwrap(), 2_000_000.0));
        // A clock step below zero counts as the smallest latency, not as a panic or a wrap.
        assert!(Latencies::of(&[-5_000]).us(0.5).unwrap() <= 0.001);
        assert_eq!(Latencies::of(&[]).us(0.5), None);
    }
}
