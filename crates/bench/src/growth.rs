//! How the cost of the transport grows with subscribers and vehicles:
//! - f. camera fan-out: 1, 2, 4, 8 subscribers (each a process of its own) of one publisher's
//!   640x480 RGB frames, on one host in shared memory (peers) and through a router over TCP
//!   (every process the router's client): frames/s each subscriber gets when the publisher
//!   sends as fast as it can, and the one-way latency each sees at the camera's 20 Hz.
//! - g. a router forwarding speed (100 Hz) and control for 1-16 vehicles: per vehicle a
//!   "simulator" process publishing vehicle/speed and a "controller" process answering each
//!   with vehicle/control, every vehicle under a namespace of its own, all through one
//!   router; messages/s forwarded, latency each way, what the router adds against the same
//!   pair connected directly, and the router's CPU.

use std::process::Stdio;

use anyhow::{Context, Result};
use serde::Serialize;

use super::child::{child_log_filter, process_cpu_s, process_peak_rss_mib};
use super::spec::{CaseSpec, RecvReport, SendReport, Transport};
use super::{median, run_groups};
use slipstream_launch::LocalRouter;

/// The frame size of the fan-out suite (the default camera's).
const FANOUT_FRAME: (u32, u32) = (640, 480);
/// The camera's rate in the fan-out latency phase.
const FANOUT_RATE_HZ: f64 = 20.0;

/// How the fan-out's frames reach their subscribers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FanoutPath {
    /// Peers on one host, frames in shared memory (descriptors over unix sockets).
    SharedMemory,
    /// Every process the client of a router on loopback, frames copied over TCP.
    Router,
}

impl FanoutPath {
    pub fn name(self) -> &'static str {
        match self {
            FanoutPath::SharedMemory => "shared memory, peers",
            FanoutPath::Router => "TCP through a router",
        }
    }
}

/// One number of subscribers on one path, medians over runs.
#[derive(Debug, Clone, Serialize)]
pub struct FanoutRow {
    pub path: FanoutPath,
    pub subscribers: usize,
    /// Frames the publisher got out per second while sending as fast as it could.
    pub published_per_s: Option<f64>,
    /// Frames per second each subscriber received: the slowest and the median subscriber.
    pub per_subscriber_min: Option<f64>,
    pub per_subscriber_median: Option<f64>,
    /// The share of the frames published that the slowest subscriber got (the rest the
    /// publisher dropped for it: congestion control `drop` keeps a slow reader from holding
    /// the camera back).
    pub slowest_got_share: Option<f64>,
    /// Frame bytes delivered per second, all subscribers together.
    pub delivered_mb_per_s: Option<f64>,
    /// One-way latency at 20 Hz: the median subscriber's p50, the largest p99.
    pub p50_us: Option<f64>,
    pub p99_us: Option<f64>,
    /// Frames sent at 20 Hz that some subscriber never got (all subscribers together)...
    pub lost: f64,
    /// ... of which its latest-only reader skipped (they arrived; a newer one came first).
    pub skipped: f64,
    /// Frames that arrived in shared memory, as a share of all received at 20 Hz.
    pub shared_memory_share: f64,
}

/// One number of vehicles through the router (or the direct baseline), medians over runs.
#[derive(Debug, Clone, Serialize)]
pub struct RouterRow {
    /// false: the baseline, one vehicle's two processes connected to each other directly.
    pub via_router: bool,
    pub vehicles: usize,
    /// Speed and control messages delivered per second, all vehicles together.
    pub messages_per_s: f64,
    /// Speed one-way (simulator -> controller): the median vehicle's p50, the largest p99.
    pub speed_p50_us: Option<f64>,
    pub speed_p99_us: Option<f64>,
    /// Control one-way (controller -> simulator), the same way.
    pub control_p50_us: Option<f64>,
    pub control_p99_us: Option<f64>,
    /// Speed p50 through the router minus the direct baseline's, same run.
    pub added_p50_us: Option<f64>,
    /// Messages sent that did not arrive (speed and control).
    pub lost: f64,
    /// The router's CPU while forwarding, % of one core.
    pub router_cpu_percent: Option<f64>,
    /// The most memory the router held during the run, MiB.
    #[serde(default)]
    pub router_peak_rss_mib: Option<f64>,
}

/// Latencies in us: (p50, p99).
fn p50_p99(ns: &[i64]) -> (Option<f64>, Option<f64>) {
    let lat = super::Latencies::of(ns);
    (lat.us(0.5), lat.us(0.99))
}

fn fanout_spec(path: FanoutPath, subscribers: usize, rate_hz: Option<f64>, quick: bool) -> CaseSpec {
    let shm = path == FanoutPath::SharedMemory;
    CaseSpec {
        // Shared memory between peers on one host over unix sockets, as `up` links its nodes.
        unix_socket: shm,
        via_router: path == FanoutPath::Router,
        subscribers,
        ..super::cases::frame_spec(Transport::Bus, FANOUT_FRAME, shm, rate_hz, quick)
    }
}

/// One run of `spec` (through a fresh router when the case says so).
/// What the router used in one run: CPU (% of a core) and its peak memory (MiB).
#[derive(Debug, Clone, Copy)]
struct RouterUse {
    cpu_percent: f64,
    peak_rss_mib: Option<f64>,
}

/// One run of a case's processes: each sender's report with its receivers', and the router's use.
type Run = (Vec<(SendReport, Vec<RecvReport>)>, Option<RouterUse>);

fn run_once(specs: &[CaseSpec]) -> Result<Run> {
    if specs.iter().any(|s| s.via_router) {
        let router = LocalRouter::start(&[], &[("RUST_LOG", child_log_filter())], Stdio::inherit())?;
        let cpu_s = || process_cpu_s(router.pid()).unwrap_or(0.0);
        let cpu_before = cpu_s();
        let out = run_groups(specs, Some(router.endpoint()))?;
        // The router's CPU over the senders' time (side by side, so the longest, session
        // opening included): what forwarding and connecting took together.
        let busy_s = out.iter().map(|(s, _)| s.elapsed_s).fold(0.0, f64::max);
        let cpu = (cpu_s() - cpu_before) / busy_s.max(1e-3);
        Ok((out, Some(RouterUse { cpu_percent: cpu * 100.0, peak_rss_mib: process_peak_rss_mib(router.pid()) })))
    } else {
        Ok((run_groups(specs, None)?, None))
    }
}

/// f. The fan-out table: for each path and number of subscribers, a throughput run and a
/// 20 Hz latency run, `repeat` times each.
pub(crate) fn fanout(counts: &[usize], quick: bool, repeat: usize) -> Result<Vec<FanoutRow>> {
    let mut rows = Vec::new();
    for path in [FanoutPath::SharedMemory, FanoutPath::Router] {
        for &n in counts {
            let mut throughput = Vec::new();
            let mut latency = Vec::new();
            // One sender and its n receivers, as fast as possible (None) or at a rate.
            let one = |rate_hz: Option<f64>| -> Result<(SendReport, Vec<RecvReport>)> {
                let spec = fanout_spec(path, n, rate_hz, quick);
                let (groups, _) =
                    run_once(std::slice::from_ref(&spec)).with_context(|| format!("fan-out {} x{n}", path.name()))?;
                groups.into_iter().next().context("one group")
            };
            for run in 0..repeat {
                eprint!("[fan-out] {} x{n}, run {} ... ", path.name(), run + 1);
                let (sent, recvs) = one(None)?;
                throughput.push(throughput_figures(&sent, &recvs));
                let (sent, recvs) = one(Some(FANOUT_RATE_HZ))?;
                let l = latency_figures(&sent, &recvs);
                eprintln!(
                    "{} frames/s each (slowest), p50 {} us",
                    slipstream_eval::fmt_opt(throughput.last().and_then(|t: &Throughput| t.min), 0),
                    slipstream_eval::fmt_opt(l.p50, 0)
                );
                latency.push(l);
            }
            let t = |f: &dyn Fn(&Throughput) -> Option<f64>| median(throughput.iter().map(f));
            let l = |f: &dyn Fn(&Latency) -> Option<f64>| median(latency.iter().map(f));
            rows.push(FanoutRow {
                path,
                subscribers: n,
                published_per_s: t(&|x| x.published),
                per_subscriber_min: t(&|x| x.min),
                per_subscriber_median: t(&|x| x.median),
                slowest_got_share: t(&|x| x.got_share),
                delivered_mb_per_s: t(&|x| x.mb),
                p50_us: l(&|x| x.p50),
                p99_us: l(&|x| x.p99),
                lost: l(&|x| Some(x.lost)).unwrap_or(0.0),
                skipped: l(&|x| Some(x.skipped)).unwrap_or(0.0),
                shared_memory_share: l(&|x| Some(x.shm_share)).unwrap_or(0.0),
            });
        }
    }
    Ok(rows)
}

struct Throughput {
    published: Option<f64>,
    min: Option<f64>,
    median: Option<f64>,
    got_share: Option<f64>,
    mb: Option<f64>,
}

fn throughput_figures(sent: &SendReport, recvs: &[RecvReport]) -> Throughput {
    let fps: Vec<Option<f64>> =
        recvs.iter().map(|r| (r.received >= 2 && r.span_s > 0.0).then(|| r.received as f64 / r.span_s)).collect();
    let mb: f64 = recvs.iter().filter(|r| r.span_s > 0.0).map(|r| r.bytes as f64 / r.span_s / 1e6).sum();
    Throughput {
        published: (sent.span_s > 0.0).then(|| sent.sent as f64 / sent.span_s),
        min: fps.iter().flatten().copied().reduce(f64::min).filter(|_| fps.iter().all(Option::is_some)),
        median: median(fps),
        got_share: recvs
            .iter()
            .map(|r| r.received as f64 / sent.sent.max(1) as f64)
            .reduce(f64::min)
            .filter(|_| sent.sent > 0),
        mb: Some(mb),
    }
}

struct Latency {
    p50: Option<f64>,
    p99: Option<f64>,
    lost: f64,
    skipped: f64,
    shm_share: f64,
}

fn latency_figures(sent: &SendReport, recvs: &[RecvReport]) -> Latency {
    let per: Vec<(Option<f64>, Option<f64>)> = recvs.iter().map(|r| p50_p99(&r.latencies_ns)).collect();
    let received: u64 = recvs.iter().map(|r| r.received).sum();
    Latency {
        p50: median(per.iter().map(|p| p.0)),
        p99: per.iter().filter_map(|p| p.1).reduce(f64::max),
        lost: recvs.iter().map(|r| sent.sent.saturating_sub(r.received) as f64).sum(),
        skipped: recvs.iter().map(|r| r.skipped as f64).sum(),
        shm_share: recvs.iter().map(|r| r.shared_memory).sum::<u64>() as f64 / received.max(1) as f64,
    }
}

fn vehicle_spec(i: usize, via_router: bool, quick: bool) -> CaseSpec {
    let count = if quick { 50 } else { 500 };
    CaseSpec {
        via_router,
        namespace: Some(format!("vehicle{i}")),
        control_echo: true,
        subscribers: 1,
        ..super::cases::speed_spec(Transport::Bus, count)
    }
}

/// g. The router table: the direct baseline, then 1..N vehicles through one router.
pub(crate) fn router(counts: &[usize], quick: bool, repeat: usize) -> Result<Vec<RouterRow>> {
    let mut cases: Vec<(bool, usize)> = vec![(false, 1)];
    cases.extend(counts.iter().map(|&n| (true, n)));
    let mut rows: Vec<RouterRow> = Vec::new();
    for (via_router, n) in cases {
        let mut runs = Vec::new();
        for run in 0..repeat {
            let what = if via_router { format!("{n} vehicle(s) through a router") } else { "1 vehicle, direct".into() };
            eprint!("[router] {what}, run {} ... ", run + 1);
            let specs: Vec<CaseSpec> = (0..n).map(|i| vehicle_spec(i, via_router, quick)).collect();
            let (groups, router_use) = run_once(&specs).with_context(|| what.clone())?;
            let r = vehicle_figures(&groups, router_use);
            eprintln!(
                "{:.0} messages/s, speed p50 {} us, {} lost",
                r.messages_per_s,
                slipstream_eval::fmt_opt(r.speed_p50_us, 0),
                r.lost
            );
            runs.push(r);
        }
        let m = |f: &dyn Fn(&RouterRow) -> Option<f64>| median(runs.iter().map(f));
        let speed_p50_us = m(&|r| r.speed_p50_us);
        let direct = rows.iter().find(|r| !r.via_router).and_then(|r| r.speed_p50_us);
        rows.push(RouterRow {
            via_router,
            vehicles: n,
            messages_per_s: m(&|r| Some(r.messages_per_s)).unwrap_or(0.0),
            speed_p50_us,
            speed_p99_us: m(&|r| r.speed_p99_us),
            control_p50_us: m(&|r| r.control_p50_us),
            control_p99_us: m(&|r| r.control_p99_us),
            added_p50_us: match (via_router, speed_p50_us, direct) {
                (true, Some(a), Some(b)) => Some(a - b),
                _ => None,
            },
            lost: m(&|r| Some(r.lost)).unwrap_or(0.0),
            router_cpu_percent: m(&|r| r.router_cpu_percent),
            router_peak_rss_mib: m(&|r| r.router_peak_rss_mib),
        });
    }
    Ok(rows)
}

/// One run's figures over all vehicles (a vehicle: one sender with one receiver).
fn vehicle_figures(groups: &[(SendReport, Vec<RecvReport>)], router: Option<RouterUse>) -> RouterRow {
    let mut speed = Vec::new();
    let mut control = Vec::new();
    let (mut delivered, mut lost) = (0u64, 0u64);
    let mut busy_s: f64 = 0.0;
    for (sent, recvs) in groups {
        busy_s = busy_s.max(sent.span_s);
        control.push(p50_p99(&sent.control_latencies_ns));
        delivered += sent.control_received;
        for r in recvs {
            speed.push(p50_p99(&r.latencies_ns));
            delivered += r.received;
            lost += sent.sent.saturating_sub(r.received);
            // Every speed message received is answered once.
            lost += r.received.saturating_sub(sent.control_received);
        }
    }
    RouterRow {
        via_router: router.is_some(),
        vehicles: groups.len(),
        messages_per_s: delivered as f64 / busy_s.max(1e-3),
        speed_p50_us: median(speed.iter().map(|p| p.0)),
        speed_p99_us: speed.iter().filter_map(|p| p.1).reduce(f64::max),
        control_p50_us: median(control.iter().map(|p| p.0)),
        control_p99_us: control.iter().filter_map(|p| p.1).reduce(f64::max),
        added_p50_us: None,
        lost: lost as f64,
        router_cpu_percent: router.map(|r| r.cpu_percent),
        router_peak_rss_mib: router.and_then(|r| r.peak_rss_mib),
    }
}

/// Both tables as markdown (either may be empty).
pub(crate) fn markdown(fanout: &[FanoutRow], router: &[RouterRow]) -> String {
    use slipstream_eval::fmt_opt;
    let mut s = String::new();
    if !fanout.is_empty() {
        s.push_str(&format!(
            "\n### f. camera fan-out: {}x{} RGB frames to N subscribers\n\nThroughput: the publisher sends as fast as it can; latency: at {FANOUT_RATE_HZ} Hz.\n\n| path | subscribers | published frames/s | frames/s per subscriber (slowest) | (median) | slowest got | delivered MB/s | p50 us | p99 us | lost (skipped by the reader) | in shm |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
            FANOUT_FRAME.0, FANOUT_FRAME.1
        ));
        for r in fanout {
            s.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} ({:.0}) | {:.0} % |\n",
                r.path.name(),
                r.subscribers,
                fmt_opt(r.published_per_s, 0),
                fmt_opt(r.per_subscriber_min, 0),
                fmt_opt(r.per_subscriber_median, 0),
                r.slowest_got_share.map_or("-".into(), |v| format!("{:.0} %", v * 100.0)),
                fmt_opt(r.delivered_mb_per_s, 0),
                fmt_opt(r.p50_us, 0),
                fmt_opt(r.p99_us, 0),
                r.lost,
                r.skipped,
                r.shared_memory_share * 100.0,
            ));
        }
    }
    if !router.is_empty() {
        s.push_str("\n### g. a router forwarding speed (100 Hz) + control for N vehicles\n\n| path | vehicles | messages/s | speed p50 us | speed p99 us | control p50 us | control p99 us | added p50 us (vs direct) | lost | router CPU % of a core | router peak memory MiB |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
        for r in router {
            s.push_str(&format!(
                "| {} | {} | {:.0} | {} | {} | {} | {} | {} | {:.0} | {} | {} |\n",
                if r.via_router { "through a router" } else { "direct (no router)" },
                r.vehicles,
                r.messages_per_s,
                fmt_opt(r.speed_p50_us, 0),
                fmt_opt(r.speed_p99_us, 0),
                fmt_opt(r.control_p50_us, 0),
                fmt_opt(r.control_p99_us, 0),
                fmt_opt(r.added_p50_us, 0),
                r.lost,
                fmt_opt(r.router_cpu_percent, 1),
                fmt_opt(r.router_peak_rss_mib, 1),
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recv(received: u64, latencies_us: &[i64], span_s: f64) -> RecvReport {
        RecvReport {
            received,
            highest_seq: None,
            bytes: received * 1000,
            latencies_ns: latencies_us.iter().map(|u| u * 1000).collect(),
            span_s,
            background_received: 0,
            shared_memory: 0,
            skipped: 0,
            handoff_ns: Vec::new(),
        }
    }

    #[test]
    fn a_vehicle_counts_lost_speed_and_unanswered_control() {
        let sent = SendReport {
            sent: 10,
            span_s: 0.1,
            control_received: 7,
            control_latencies_ns: vec![50_000; 7],
            ..SendReport::default()
        };
        let router = RouterUse { cpu_percent: 12.0, peak_rss_mib: Some(20.0) };
        let row = vehicle_figures(&[(sent, vec![recv(9, &[100; 9], 0.09)])], Some(router));
        // 1 speed message lost, 2 of the 9 answers lost: 16 delivered in 0.1 s.
        assert_eq!(row.lost, 3.0);
        assert!((row.messages_per_s - 160.0).abs() < 1e-9);
        // Percentiles to 3 significant digits (an HDR histogram).
        assert!(close(row.speed_p50_us, 100.0) && close(row.control_p50_us, 50.0), "{row:?}");
        assert!(row.via_router);
        assert_eq!((row.router_cpu_percent, row.router_peak_rss_mib), (Some(12.0), Some(20.0)));
    }

    #[test]
    fn fanout_takes_the_slowest_subscriber_and_every_loss() {
        let sent = SendReport { sent: 10, span_s: 1.0, ..SendReport::default() };
        let t = throughput_figures(&sent, &[recv(10, &[], 1.0), recv(20, &[], 1.0), recv(30, &[], 2.0)]);
        assert_eq!(t.min, Some(10.0));
        assert_eq!(t.median, Some(15.0));
        assert_eq!(t.got_share, Some(1.0));
        let l = latency_figures(&sent, &[recv(10, &[100, 200, 300], 1.0), recv(8, &[400, 500, 600], 1.0)]);
        assert_eq!(l.lost, 2.0);
        assert!(close(l.p50, 350.0) && close(l.p99, 600.0), "{:?} {:?}", l.p50, l.p99);
    }

    /// Within the 0.1 % of the bench's percentiles.
    fn close(v: Option<f64>, want: f64) -> bool {
        v.is_some_and(|v| (v / want - 1.0).abs() < 1e-3)
    }
}
