//! e. How the cost grows with complete loops (`slipstream bench scale`): 1, 2, 4, 8 loops
//! (slipstream-sim, slipstream-detect and slipstream-acc each, camera perception) run in
//! realtime side by side on this machine, each in a namespace and unix sockets of its own,
//! started through the launch layer like `up` and `eval acc`. Per number of loops: the
//! simulators' real-time factors, the loop's latency (camera frame published -> command
//! applied, from the stamps the messages carry, as `up` shows it), and the CPU each loop
//! takes; and the largest number that still holds real time and the 5 ms loop.

use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;

use slipstream_acc::PerceptionSource;
use slipstream_launch::{ClockMode, LinkKind, LoopRun, LoopSpec, Network, NODE_POLL};
use slipstream_observe::latency::{LatencyWatch, WHOLE_LOOP};
use slipstream_sim::Scenario;

/// A loop holds real time when its simulator runs at least this fast.
pub(crate) const MIN_RTF: f64 = 0.97;
/// ... and its frame -> applied latency p50 is at most this (the loop's aim).
pub(crate) const MAX_LOOP_P50_MS: f64 = 5.0;
/// The scenario every loop drives.
const SCENARIO: &str = "cut-in";

/// One number of loops, side by side.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleRow {
    pub loops: usize,
    /// The simulators' real-time factors: the slowest and the median.
    pub rtf_min: f64,
    pub rtf_median: f64,
    /// Frame published -> command applied: the median of the loops' p50s, the largest p99.
    pub loop_p50_ms: Option<f64>,
    pub loop_p99_ms: Option<f64>,
    /// CPU time of a loop's three processes per second of wall time (1.0: one core busy).
    pub cpu_per_loop: f64,
    /// Every loop held real time and the 5 ms loop.
    pub holds: bool,
}

/// Runs `loops` side by side for `duration_s` simulated seconds each, for every count.
pub(crate) fn run(counts: &[usize], duration_s: f64) -> Result<Vec<ScaleRow>> {
    let rt = tokio::runtime::Runtime::new()?;
    let mut rows = Vec::new();
    for &n in counts {
        eprint!("[scale] {n} loop(s) in realtime for {duration_s} s ... ");
        let row = rt.block_on(side_by_side(n, duration_s)).with_context(|| format!("{n} loops side by side"))?;
        eprintln!(
            "RTF {:.2} (slowest), loop p50 {} ms, {:.0} % of a core per loop",
            row.rtf_min,
            row.loop_p50_ms.map_or("-".into(), |v| format!("{v:.2}")),
            row.cpu_per_loop * 100.0
        );
        rows.push(row);
    }
    Ok(rows)
}

/// The largest number of loops that held real time and the 5 ms loop (and every smaller one).
pub(crate) fn largest_holding(rows: &[ScaleRow]) -> Option<usize> {
    let mut sorted: Vec<&ScaleRow> = rows.iter().collect();
    sorted.sort_by_key(|r| r.loops);
    sorted.iter().take_while(|r| r.holds).last().map(|r| r.loops)
}

async fn side_by_side(n: usize, duration_s: f64) -> Result<ScaleRow> {
    let scenario = Scenario::find(SCENARIO).map_err(anyhow::Error::msg)?;
    let spec = LoopSpec {
        scenario: SCENARIO.into(),
        duration_s,
        clock: ClockMode::Realtime,
        perception: PerceptionSource::Camera,
        set_speed_mps: scenario.ego().controller_set_speed_mps(),
        time_gap_s: scenario.ego().time_gap_s,
        vehicle: Some(LoopSpec::vehicle_of(&scenario)),
        faults: None,
        link: LinkKind::Unix,
        own: Default::default(),
        egos: Vec::new(),
    };
    let logs = std::env::temp_dir().join(format!("slipstream-bench-scale-{}", std::process::id()));
    let cpu_before = children_cpu_s();
    let mut runs = Vec::new();
    for i in 0..n {
        let network =
            Network::Isolated { topics: None, namespace: format!("bench-scale-{}-{n}-{i}", std::process::id()) };
        let run = LoopRun::open(spec.clone(), network, &logs.join(format!("{n}-{i}")), "bench-scale").await?;
        let watch = LatencyWatch::start(run.bus(), true).await?;
        runs.push((run, watch));
    }
    // Controllers first everywhere, then the simulators, so that they start together.
    let started = Instant::now();
    for (run, _) in &mut runs {
        run.start().await?;
    }
    let limit = Duration::from_secs_f64(duration_s * 3.0 + 60.0);
    loop {
        let progress: Vec<_> = runs.iter_mut().map(|(r, _)| r.check()).collect();
        if let Some(p) = progress.iter().find(|p| !p.died.is_empty()) {
            anyhow::bail!("{} ended before the run was over (logs in {})", p.died.join(", "), logs.display());
        }
        if progress.iter().all(|p| p.sim_ended.is_some()) {
            break;
        }
        anyhow::ensure!(started.elapsed() < limit, "the loops did not finish within {limit:?}");
        tokio::time::sleep(NODE_POLL).await;
    }
    let wall_s = started.elapsed().as_secs_f64();
    let mut rtfs = Vec::new();
    let (mut p50s, mut p99) = (Vec::new(), None::<f64>);
    for (run, watch) in &mut runs {
        run.stop().await;
        rtfs.push(run.sim_report()?.real_time_factor);
        let stats = watch.latency.lock().stats(false);
        let whole = &stats[WHOLE_LOOP];
        p50s.extend(whole.p50_ms);
        p99 = whole.p99_ms.map(|v| p99.map_or(v, |p: f64| p.max(v))).or(p99);
    }
    let cpu_s = children_cpu_s() - cpu_before;
    for (run, watch) in runs {
        drop(watch);
        run.close().await;
    }
    let _ = std::fs::remove_dir_all(&logs);
    rtfs.sort_by(f64::total_cmp);
    p50s.sort_by(f64::total_cmp);
    let rtf_min = rtfs.first().copied().unwrap_or(0.0);
    let loop_p50_ms = p50s.get(p50s.len() / 2).copied();
    Ok(ScaleRow {
        loops: n,
        rtf_min,
        rtf_median: rtfs[rtfs.len() / 2],
        loop_p50_ms,
        loop_p99_ms: p99,
        cpu_per_loop: cpu_s / n as f64 / wall_s.max(1e-9),
        holds: rtf_min >= MIN_RTF && p50s.len() == n && p50s.iter().all(|p| *p <= MAX_LOOP_P50_MS),
    })
}

/// User and system CPU seconds of this process's children that have ended (and been waited
/// for): the loops' nodes, once stopped.
fn children_cpu_s() -> f64 {
    // SAFETY: getrusage fills the struct we own; RUSAGE_CHILDREN is a valid `who`.
    let usage = unsafe {
        let mut u: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_CHILDREN, &mut u);
        u
    };
    let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 / 1e6;
    secs(usage.ru_utime) + secs(usage.ru_stime)
}

/// The rows as a markdown table, with the largest number that holds.
pub(crate) fn markdown(rows: &[ScaleRow]) -> String {
    let mut s = String::from(
        "\n### e. complete loops side by side (realtime, camera)\n\n| loops | RTF slowest | RTF median | loop p50 ms | loop p99 ms | CPU per loop (% of a core) | holds RTF and 5 ms |\n|---|---|---|---|---|---|---|\n",
    );
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    for r in rows {
        s.push_str(&format!(
            "| {} | {:.2} | {:.2} | {} | {} | {:.0} | {} |\n",
            r.loops,
            r.rtf_min,
            r.rtf_median,
            ms(r.loop_p50_ms),
            ms(r.loop_p99_ms),
            r.cpu_per_loop * 100.0,
            if r.holds { "yes" } else { "no" }
        ));
    }
    s.push_str(&format!(
        "\nLargest number of loops holding real time (RTF >= {MIN_RTF}) and the loop's p50 <= {MAX_LOOP_P50_MS} ms: {}\n",
        largest_holding(rows).map_or("none".to_string(), |n| n.to_string())
    ));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(loops: usize, holds: bool) -> ScaleRow {
        ScaleRow {
            loops,
            rtf_min: 1.0,
            rtf_median: 1.0,
            loop_p50_ms: Some(3.0),
            loop_p99_ms: Some(5.0),
            cpu_per_loop: 0.2,
            holds,
        }
    }

    #[test]
    fn the_largest_holding_count_stops_at_the_first_that_fails() {
        assert_eq!(largest_holding(&[row(1, true), row(2, true), row(4, false), row(8, true)]), Some(2));
        assert_eq!(largest_holding(&[row(2, true), row(1, true)]), Some(2));
        assert_eq!(largest_holding(&[row(1, false), row(2, true)]), None);
        assert!(markdown(&[row(1, true)]).contains("holding real time (RTF >= 0.97) and the loop's p50 <= 5 ms: 1"));
    }
}
