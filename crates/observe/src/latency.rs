//! The loop's latency, hop by hop, from the stamps the messages carry (wire format v2):
//!
//! ```text
//! camera frame published        Detections.frame_stamp_pub_ns
//!   -> detections published     Detections header.stamp_pub_ns   = Control.perception_stamp_pub_ns
//!   -> control published        Control header.stamp_pub_ns      = State.control_timing.command_stamp_pub_ns
//!   -> control applied          State.control_timing.applied_ns
//! ```
//!
//! Each hop counts once per message that moved the loop on: the first command computed from a
//! perception message (later ones reuse it), the first application of a command. All stamps
//! are publishers' wall clocks, so the figures hold on one host or hosts with synchronised
//! clocks.

use std::collections::HashMap;

use serde::Serialize;

/// The hops, in loop order; the constants below index them.
pub const HOPS: [&str; 4] = ["frame -> detections", "detections -> control", "control -> applied", "frame -> applied"];
pub(crate) const FRAME_TO_DETECTIONS: usize = 0;
pub(crate) const DETECTIONS_TO_CONTROL: usize = 1;
pub(crate) const CONTROL_TO_APPLIED: usize = 2;
/// The whole loop: frame published -> control applied.
pub const WHOLE_LOOP: usize = 3;
/// The same, short (the live view).
pub const HOPS_SHORT: [&str; 4] = ["frame>det", "det>ctl", "ctl>applied", "loop"];

/// Samples kept per hop for the live view's percentiles.
const LIVE_WINDOW: usize = 200;

#[derive(Debug, Default)]
pub struct LoopLatency {
    /// Perception message publish stamp -> the stamp of the data it came from (the camera
    /// frame for detections; itself for ground truth, which the simulator publishes with the
    /// frame). Removed when used; entries never used are dropped after `KEEP_NS`.
    origin: HashMap<u64, u64>,
    /// Reacting command's publish stamp -> the perception stamp it reacted to.
    basis: HashMap<u64, u64>,
    /// The newest perception a command reacted to, and the newest command applied: each
    /// stream is in publish order, so a stamp not newer than these was counted already.
    last_basis: u64,
    last_applied: u64,
    /// Per hop: (publish time of the later message, ns since the epoch; latency, ns).
    samples: [Vec<(u64, i64)>; 4],
    /// Only the newest `LIVE_WINDOW` samples matter (the live view, open for hours): older
    /// ones are dropped instead of kept for a report.
    live_only: bool,
}

/// How long an unused trace entry is kept (a perception no command used, a command never
/// applied): bounded memory however long the run.
const KEEP_NS: u64 = 10_000_000_000;

/// Percentiles of one hop.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct HopStats {
    pub hop: &'static str,
    pub count: usize,
    pub p50_ms: Option<f64>,
    pub p99_ms: Option<f64>,
    pub max_ms: Option<f64>,
}

impl LoopLatency {
    /// A detections message: published at `pub_ns`, from the frame published at `frame_pub_ns`.
    pub(crate) fn on_detections(&mut self, pub_ns: u64, frame_pub_ns: u64) {
        insert_bounded(&mut self.origin, pub_ns, frame_pub_ns);
        self.push(FRAME_TO_DETECTIONS, pub_ns, pub_ns as i64 - frame_pub_ns as i64);
    }

    /// A ground-truth message (the perception of `--perception ground-truth`).
    pub(crate) fn on_ground_truth(&mut self, pub_ns: u64) {
        insert_bounded(&mut self.origin, pub_ns, pub_ns);
    }

    /// A command published at `pub_ns`, computed from the perception published at `basis`;
    /// the first command from a perception is the loop's reaction to it.
    pub fn on_command(&mut self, pub_ns: u64, basis: Option<u64>) {
        let Some(basis) = basis else { return };
        if basis <= self.last_basis {
            return;
        }
        self.last_basis = basis;
        insert_bounded(&mut self.basis, pub_ns, basis);
        self.push(DETECTIONS_TO_CONTROL, pub_ns, pub_ns as i64 - basis as i64);
    }

    /// A state saying the command published at `command_pub_ns` was first applied at
    /// `applied_ns` (every state while the command holds says so: counted once).
    pub(crate) fn on_applied(&mut self, command_pub_ns: u64, applied_ns: u64) {
        if command_pub_ns <= self.last_applied {
            return;
        }
        self.last_applied = command_pub_ns;
        self.push(CONTROL_TO_APPLIED, applied_ns, applied_ns as i64 - command_pub_ns as i64);
        // The whole loop, once per perception message: its reacting command applied.
        let Some(basis) = self.basis.remove(&command_pub_ns) else { return };
        if let Some(origin) = self.origin.remove(&basis) {
            self.push(WHOLE_LOOP, applied_ns, applied_ns as i64 - origin as i64);
        }
    }

    /// Keeps only what the live figures need ([`LatencyWatch::start_live`]).
    pub fn live_only() -> LoopLatency {
        LoopLatency { live_only: true, ..LoopLatency::default() }
    }

    fn push(&mut self, hop: usize, t_ns: u64, latency_ns: i64) {
        let s = &mut self.samples[hop];
        s.push((t_ns, latency_ns));
        // Trimmed in batches: a drain per sample would move the window every time.
        if self.live_only && s.len() >= 2 * LIVE_WINDOW {
            s.drain(..s.len() - LIVE_WINDOW);
        }
    }

    /// Percentiles over every sample, or over the newest `LIVE_WINDOW` of each hop.
    pub fn stats(&self, live: bool) -> Vec<HopStats> {
        HOPS.iter()
            .zip(&self.samples)
            .map(|(hop, s)| {
                let from = if live { s.len().saturating_sub(LIVE_WINDOW) } else { 0 };
                let mut v: Vec<i64> = s[from..].iter().map(|x| x.1).collect();
                v.sort_unstable();
                let pct = |p: f64| -> Option<f64> {
                    (!v.is_empty()).then(|| v[((v.len() - 1) as f64 * p).round() as usize] as f64 / 1e6)
                };
                HopStats {
                    hop,
                    count: v.len(),
                    p50_ms: pct(0.5),
                    p99_ms: pct(0.99),
                    max_ms: v.last().map(|x| *x as f64 / 1e6),
                }
            })
            .collect()
    }

    /// Every sample of a hop, as (seconds since `t0_ns`, milliseconds).
    pub fn series(&self, hop: usize, t0_ns: u64) -> Vec<(f64, f64)> {
        self.samples[hop].iter().map(|(t, v)| ((*t as f64 - t0_ns as f64) / 1e9, *v as f64 / 1e6)).collect()
    }
}

/// Inserts, and now and then drops the entries older than `KEEP_NS` (keys are wall-clock ns).
fn insert_bounded(map: &mut HashMap<u64, u64>, key: u64, value: u64) {
    map.insert(key, value);
    if map.len().is_multiple_of(1024) {
        map.retain(|k, _| k + KEEP_NS >= key);
    }
}

/// The loop's latency, fed from a session's subscriptions to the messages that carry its
/// stamps (detections, control, state; ground truth as the perception without the camera):
/// what `up` shows and `bench scale` measures per loop. Replayed messages (`slipstream play`
/// beside the loop) carry a recording's stamps and are left out.
pub struct LatencyWatch {
    pub latency: std::sync::Arc<parking_lot::Mutex<LoopLatency>>,
    _subs: [slipstream_contract::bus::CallbackSubscriber; 4],
}

impl LatencyWatch {
    pub async fn start(
        bus: &slipstream_contract::Bus,
        camera: bool,
    ) -> Result<LatencyWatch, slipstream_contract::BusError> {
        Self::start_with(bus, camera, LoopLatency::default()).await
    }

    /// The same for live figures only: memory bounded however long it watches (the view).
    pub async fn start_live(
        bus: &slipstream_contract::Bus,
        camera: bool,
    ) -> Result<LatencyWatch, slipstream_contract::BusError> {
        Self::start_with(bus, camera, LoopLatency::live_only()).await
    }

    async fn start_with(
        bus: &slipstream_contract::Bus,
        camera: bool,
        latency: LoopLatency,
    ) -> Result<LatencyWatch, slipstream_contract::BusError> {
        use slipstream_contract::bus::is_replayed;
        use slipstream_contract::topics;
        let latency = std::sync::Arc::new(parking_lot::Mutex::new(latency));
        let l = latency.clone();
        let detections = bus
            .subscribe_with(topics::PERCEPTION_OBJECTS, move |d| {
                if !is_replayed(d.source.as_deref()) {
                    l.lock().on_detections(d.header.stamp_pub_ns, d.msg.frame_stamp_pub_ns)
                }
            })
            .await?;
        let l = latency.clone();
        let control = bus
            .subscribe_with(topics::VEHICLE_CONTROL, move |c| {
                if !is_replayed(c.source.as_deref()) {
                    l.lock().on_command(c.header.stamp_pub_ns, c.msg.perception_stamp_pub_ns)
                }
            })
            .await?;
        let l = latency.clone();
        let state = bus
            .subscribe_with(topics::VEHICLE_STATE, move |s| {
                if let Some(t) = s.msg.control_timing.filter(|_| !is_replayed(s.source.as_deref())) {
                    l.lock().on_applied(t.command_stamp_pub_ns, t.applied_ns);
                }
            })
            .await?;
        let l = latency.clone();
        let truth = bus
            .subscribe_with(topics::OBJECTS, move |o| {
                if !camera && !is_replayed(o.source.as_deref()) {
                    l.lock().on_ground_truth(o.header.stamp_pub_ns)
                }
            })
            .await?;
        Ok(LatencyWatch { latency, _subs: [detections, control, state, truth] })
    }
}

/// The smallest constant time gap a string of vehicles with this loop delay stays stable at:
/// h > 2 (delay + actuator lag), the classic bound for a constant-time-gap policy with a
/// delayed first-order actuator.
pub fn min_stable_time_gap_s(delay_s: f64, actuator_lag_s: f64) -> f64 {
    2.0 * (delay_s + actuator_lag_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_live_only_latency_keeps_a_bounded_window_with_the_newest_samples() {
        let mut l = LoopLatency::live_only();
        for k in 0..10_000u64 {
            l.on_detections(1_000 + k * 10, k * 10);
        }
        let s = &l.samples[FRAME_TO_DETECTIONS];
        assert!(s.len() < 2 * LIVE_WINDOW && s.len() >= LIVE_WINDOW, "{}", s.len());
        assert_eq!(s.last().unwrap().0, 1_000 + 9_999 * 10);
        assert_eq!(l.stats(true)[FRAME_TO_DETECTIONS].count, LIVE_WINDOW);
    }

    #[test]
    fn each_hop_counts_the_message_that_moved_the_loop_on() {
        let ms = 1_000_000u64;
        let mut l = LoopLatency::default();
        // Frame at 100 ms, detections at 103, commands at 105 and 115 from them, the first
        // applied at 110 (and reported again at 120), the second at 120.
        l.on_detections(103 * ms, 100 * ms);
        l.on_command(105 * ms, Some(103 * ms));
        l.on_command(115 * ms, Some(103 * ms));
        l.on_command(116 * ms, None);
        l.on_applied(105 * ms, 110 * ms);
        l.on_applied(105 * ms, 110 * ms);
        l.on_applied(115 * ms, 120 * ms);
        let s = l.stats(false);
        let p50: Vec<Option<f64>> = s.iter().map(|h| h.p50_ms).collect();
        assert_eq!(p50, vec![Some(3.0), Some(2.0), Some(5.0), Some(10.0)]);
        let counts: Vec<usize> = s.iter().map(|h| h.count).collect();
        assert_eq!(counts, vec![1, 1, 2, 1], "one reaction per perception, one total per perception");
        assert!((min_stable_time_gap_s(0.01, 0.0) - 0.02).abs() < 1e-12);
    }

    #[test]
    fn unused_entries_do_not_pile_up() {
        let mut l = LoopLatency::default();
        // An hour of 20 Hz frames that no command ever used.
        for i in 0..72_000u64 {
            l.on_detections(i * 50_000_000 + 3_000_000, i * 50_000_000);
        }
        assert!(l.origin.len() <= 1024 + 200, "{}", l.origin.len());
        assert_eq!(l.stats(false)[0].count, 72_000);
    }
}
