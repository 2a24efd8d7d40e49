//! `slipstream soak`: the loop for a long while, with every process's memory, open files and
//! threads sampled, to show nothing grows once it has started.
//!
//! The loop runs through the launch layer (the same path as `up` and `eval acc`) on loopback
//! ports and a namespace of its own, in lockstep by default (every control step must be
//! answered: a lost one shows as a lockstep timeout). The scenario is made for the length of
//! the run: a 100 km road, a lead and two vehicles beside the ego at a crawl, so the camera
//! sees three vehicles the whole time. Every `--sample-s` the launcher reads /proc for each
//! node and for itself: resident memory (VmRSS), threads, open file descriptors. After the
//! warm-up, growth of any of them is a finding; the aim is RSS drift < 5 %.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use crate::acc::PerceptionSource;
use crate::launch::{ClockMode, LoopRun, LoopSpec, Network, NODE_POLL};

/// RSS may grow by at most this fraction between the end of the warm-up and the end.
pub const RSS_DRIFT_AIM: f64 = 0.05;
/// Speed of every vehicle of the soak scenario (a traffic-jam crawl): 100 km last over
/// 66,000 simulated seconds, longer than 30 minutes of lockstep at the ~23x real time of this
/// machine.
const SOAK_SPEED_MPS: f64 = 1.5;
const SOAK_ROAD_M: f64 = 100_000.0;

#[derive(Debug, Clone, clap::Args)]
pub struct SoakArgs {
    /// How long to run, minutes of wall time
    #[arg(long, default_value_t = 30.0, value_parser = super::top::positive)]
    pub minutes: f64,
    /// How the simulator's clock runs (lockstep: every step answered; fast: unpaced, the
    /// controllers may fall behind)
    #[arg(long, value_enum, default_value = "lockstep")]
    pub mode: ClockMode,
    /// Where the ACC's vehicles ahead come from
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// Seconds between samples
    #[arg(long, default_value_t = 10.0, value_parser = super::top::positive)]
    pub sample_s: f64,
    /// Growth is judged from this many minutes on [default: a tenth of the run, at most 3]
    #[arg(long, value_parser = super::top::positive)]
    pub warmup_minutes: Option<f64>,
    /// Where soak.json, soak.csv, soak.png and the nodes' logs go [default: reports/soak-<UTC time>]
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Meanwhile publish this many malformed payloads a second, spread over every key of the
    /// loop (valid messages mutated, and random bytes): the nodes must count and drop them and
    /// keep running, their memory flat. Bounded by --minutes
    #[arg(long, value_name = "MSGS_PER_S", default_value_t = 0)]
    pub garbage_rate: u32,
    /// Print the report as JSON
    #[arg(long)]
    pub json: bool,
}

/// One process at one moment.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Usage {
    pub rss_kib: u64,
    pub threads: u64,
    pub fds: u64,
}

/// Reads /proc/<pid> (through `procfs`): resident memory, threads, open file descriptors.
pub fn usage(pid: u32) -> Option<Usage> {
    let process = procfs::process::Process::new(i32::try_from(pid).ok()?).ok()?;
    let status = process.status().ok()?;
    let fds = process.fd_count().ok()? as u64;
    Some(Usage { rss_kib: status.vmrss?, threads: status.threads, fds })
}

#[derive(Debug, Clone, Serialize)]
pub struct Sample {
    pub t_min: f64,
    pub sim_time_s: f64,
    /// Per process, in the order of `SoakReport::processes`; None once it has gone.
    pub usage: Vec<Option<Usage>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ProcessVerdict {
    pub process: String,
    pub warm: Option<Usage>,
    pub end: Option<Usage>,
    pub rss_drift: Option<f64>,
    pub pass: bool,
}

#[derive(Debug, Clone, Serialize)]
pub struct SoakReport {
    pub command: String,
    pub minutes: f64,
    pub mode: ClockMode,
    pub perception: PerceptionSource,
    pub warmup_minutes: f64,
    pub processes: Vec<String>,
    pub samples: Vec<Sample>,
    pub verdicts: Vec<ProcessVerdict>,
    pub sim_time_s: f64,
    pub steps: u64,
    pub lockstep_timeouts: u64,
    pub control_timeouts: u64,
    pub died: Vec<String>,
    /// Malformed payloads published (--garbage-rate), and the ones the ACC and the simulator
    /// counted as undecodable on their inputs.
    pub garbage_sent: u64,
    pub garbage_rejected: u64,
    pub pass: bool,
    pub report_dir: PathBuf,
}

/// Every key of the loop's topics in this namespace.
fn keys(bus: &crate::Bus) -> Vec<zenoh::key_expr::OwnedKeyExpr> {
    crate::topics::Topic::ALL.iter().map(|t| bus.topics().key(*t)).collect()
}

/// Publishes `rate` malformed payloads a second, round-robin over `keys`, until `stop`: the
/// wire examples of every message type mutated (a tenth of them still decode) and random
/// bytes. Returns how many were sent.
async fn flood(
    session: zenoh::Session,
    keys: Vec<zenoh::key_expr::OwnedKeyExpr>,
    rate: u32,
    stop: Arc<AtomicBool>,
) -> u64 {
    let examples: Vec<Vec<u8>> = crate::msg::examples().into_iter().map(|(_, b)| b).collect();
    let others: Vec<&[u8]> = examples.iter().map(Vec::as_slice).collect();
    let mut rng = crate::sim::SimRng::new(15);
    let tick = Duration::from_millis(10);
    let per_tick = (rate as f64 * tick.as_secs_f64()).ceil() as u64;
    let mut interval = tokio::time::interval(tick);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let started = Instant::now();
    let mut sent = 0u64;
    while !stop.load(Ordering::SeqCst) {
        interval.tick().await;
        // Never ahead of the rate, even after a stall.
        let due = (started.elapsed().as_secs_f64() * rate as f64) as u64;
        for _ in 0..per_tick.min(due.saturating_sub(sent)) {
            let key = &keys[(sent % keys.len() as u64) as usize];
            let payload = if rng.below(4) == 0 {
                (0..rng.below(256)).map(|_| rng.next_u64() as u8).collect()
            } else {
                let base = &examples[rng.below(examples.len() as u64) as usize];
                super::fuzz::mutate(&mut rng, base, &others, false)
            };
            use zenoh::Wait;
            let _ = session.put(key, payload).wait();
            sent += 1;
        }
    }
    sent
}

/// The scenario of a soak: long road, a crawl, three vehicles in view.
fn scenario_text() -> String {
    let v = SOAK_SPEED_MPS;
    format!(
        r#"{{
  name: "soak",
  description: "Generated by slipstream soak: {v} m/s behind a lead on a {km} km road, a van and a truck beside.",
  duration_s: {duration},
  seed: 11,
  road: {{ lanes: 3, lane_width_m: 3.5, length_m: {SOAK_ROAD_M} }},
  ego: {{ lane: 1, speed_mps: {v}, set_speed_mps: 30 }},
  traffic: [
    {{ lane: 1, gap_m: 30, speed_mps: {v} }},
    {{ lane: 0, gap_m: 20, speed_mps: {v}, class: "van" }},
    {{ lane: 2, gap_m: 45, speed_mps: {v}, class: "truck" }},
  ],
}}
"#,
        km = SOAK_ROAD_M / 1000.0,
        duration = ((SOAK_ROAD_M - 200.0) / v).floor()
    )
}

/// Growth from the warm-up sample to the last: RSS within the aim, no more threads or files.
fn verdict(process: &str, i: usize, samples: &[Sample], warmup_min: f64) -> ProcessVerdict {
    let warm = samples.iter().find(|s| s.t_min >= warmup_min).and_then(|s| s.usage[i]);
    let end = samples.last().and_then(|s| s.usage[i]);
    let rss_drift = match (warm, end) {
        (Some(w), Some(e)) if w.rss_kib > 0 => Some((e.rss_kib as f64 - w.rss_kib as f64) / w.rss_kib as f64),
        _ => None,
    };
    let pass = match (warm, end, rss_drift) {
        (Some(w), Some(e), Some(d)) => d < RSS_DRIFT_AIM && e.threads <= w.threads && e.fds <= w.fds,
        _ => false,
    };
    ProcessVerdict { process: process.to_string(), warm, end, rss_drift, pass }
}

pub fn run(args: &SoakArgs, connect: &crate::config::ConnectArgs) -> Result<SoakReport> {
    let dir = match &args.report {
        Some(d) => d.clone(),
        None => super::fresh_report_dir("soak")?,
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
    let scenario_path = dir.join("soak-scenario.json5");
    std::fs::write(&scenario_path, scenario_text())?;
    let scenario = crate::sim::Scenario::find(&scenario_path.display().to_string())?;
    let warmup_min = args.warmup_minutes.unwrap_or((args.minutes / 10.0).min(3.0));
    anyhow::ensure!(warmup_min < args.minutes, "--warmup-minutes must be shorter than --minutes");
    let spec = LoopSpec {
        scenario: scenario_path.display().to_string(),
        duration_s: scenario.duration_s,
        clock: args.mode,
        perception: args.perception,
        set_speed_mps: 30.0,
        time_gap_s: None,
        vehicle: Some(LoopSpec::vehicle_of(&scenario)),
        faults: None,
        link: Default::default(),
        own: Default::default(),
        egos: Vec::new(),
    };
    let namespace = format!("soak-{}", std::process::id());
    let network = Network::Isolated { topics: connect.topics.clone(), namespace };
    let rt = tokio::runtime::Runtime::new()?;
    let report = rt.block_on(async {
        let mut lp = LoopRun::open(spec, network, &dir.join("logs"), "soak").await?;
        let clock = lp.bus().subscriber(crate::topics::SIM_CLOCK).await?;
        lp.start().await?;
        let stop_garbage = Arc::new(AtomicBool::new(false));
        let garbage = match args.garbage_rate {
            0 => None,
            rate => Some(tokio::spawn(flood(lp.bus().session().clone(), keys(lp.bus()), rate, stop_garbage.clone()))),
        };
        let mut processes = vec![("slipstream (launcher)".to_string(), std::process::id())];
        processes.extend(lp.node_pids());
        eprintln!(
            "slipstream soak: {:.1} min, {} clock, {} perception; processes {}; report in {}",
            args.minutes,
            args.mode.name(),
            args.perception.name(),
            processes.iter().map(|(n, p)| format!("{n} ({p})")).collect::<Vec<_>>().join(", "),
            dir.display()
        );
        let (progress, samples, sim_time_s) = sample_until_over(&mut lp, &clock, &processes, args).await;
        stop_garbage.store(true, Ordering::SeqCst);
        let garbage_sent = match garbage {
            Some(task) => task.await.unwrap_or(0),
            None => 0,
        };
        lp.stop().await;
        let sim = lp.sim_report().ok();
        let garbage_rejected: u64 = lp.inputs().iter().map(|i| i.stats.decode_errors).sum();
        lp.close().await;
        let verdicts: Vec<ProcessVerdict> =
            processes.iter().enumerate().map(|(i, (n, _))| verdict(n, i, &samples, warmup_min)).collect();
        let lockstep_timeouts = sim.as_ref().map_or(0, |s| s.lockstep_timeouts);
        let control_timeouts = sim.as_ref().map_or(0, |s| s.control_timeouts);
        let pass = verdicts.iter().all(|v| v.pass)
            && progress.died.is_empty()
            && sim.is_some()
            && (args.mode != ClockMode::Lockstep || lockstep_timeouts == 0);
        anyhow::Ok(SoakReport {
            command: std::env::args().collect::<Vec<_>>().join(" "),
            minutes: args.minutes,
            mode: args.mode,
            perception: args.perception,
            warmup_minutes: warmup_min,
            processes: processes.into_iter().map(|(n, _)| n).collect(),
            samples,
            verdicts,
            sim_time_s: sim.as_ref().map_or(sim_time_s, |s| s.sim_time_s),
            steps: sim.as_ref().map_or(0, |s| s.steps),
            lockstep_timeouts,
            control_timeouts,
            died: progress.died,
            garbage_sent,
            garbage_rejected,
            pass,
            report_dir: dir.clone(),
        })
    })?;
    write_outputs(&report, &dir)?;
    Ok(report)
}

/// Samples every process's usage every `sample_s` until the loop is over, `minutes` have
/// passed or a stop request comes. Returns how the loop stood then, the samples (the last
/// one taken before anything stops) and the newest simulated time.
async fn sample_until_over(
    lp: &mut LoopRun,
    clock: &crate::bus::Subscriber<crate::msg::SimClock>,
    processes: &[(String, u32)],
    args: &SoakArgs,
) -> (crate::launch::Progress, Vec<Sample>, f64) {
    let started = Instant::now();
    let every = Duration::from_secs_f64(args.sample_s);
    let mut next = started;
    let mut samples = Vec::new();
    let mut sim_time_s = 0.0;
    let ctrl_c = crate::cli::stop_requested();
    tokio::pin!(ctrl_c);
    let progress = loop {
        while let Some(c) = clock.try_recv() {
            sim_time_s = c.header.stamp_sim_ns as f64 / 1e9;
        }
        let now = Instant::now();
        let t_min = now.duration_since(started).as_secs_f64() / 60.0;
        if now >= next {
            let usage = processes.iter().map(|(_, pid)| usage(*pid)).collect();
            samples.push(Sample { t_min, sim_time_s, usage });
            next += every;
            eprintln!("  {t_min:6.2} min  sim {sim_time_s:8.0} s  {}", line(processes, samples.last()));
        }
        let progress = lp.check();
        if progress.over() || t_min >= args.minutes {
            break progress;
        }
        tokio::select! {
            signal = &mut ctrl_c => { eprintln!("{signal}: stopping"); break lp.check() },
            _ = tokio::time::sleep(NODE_POLL.max(Duration::from_millis(200))) => {}
        }
    };
    // The last sample before anything stops.
    let t_min = started.elapsed().as_secs_f64() / 60.0;
    samples.push(Sample { t_min, sim_time_s, usage: processes.iter().map(|(_, pid)| usage(*pid)).collect() });
    (progress, samples, sim_time_s)
}

fn line(processes: &[(String, u32)], s: Option<&Sample>) -> String {
    let Some(s) = s else { return String::new() };
    processes
        .iter()
        .zip(&s.usage)
        .map(|((n, _), u)| match u {
            Some(u) => format!(
                "{}: {:.1} MB {} thr {} fd",
                n.trim_start_matches("slipstream-"),
                u.rss_kib as f64 / 1024.0,
                u.threads,
                u.fds
            ),
            None => format!("{n}: gone"),
        })
        .collect::<Vec<_>>()
        .join(" | ")
}

/// soak.json, soak.csv and soak.png in `dir`.
fn write_outputs(r: &SoakReport, dir: &Path) -> Result<()> {
    std::fs::write(dir.join("soak.json"), serde_json::to_string_pretty(r)?)?;
    let mut csv = csv::Writer::from_path(dir.join("soak.csv"))?;
    csv.write_record(["t_min", "sim_time_s", "process", "rss_kib", "threads", "fds"])?;
    for s in &r.samples {
        for (p, u) in r.processes.iter().zip(&s.usage) {
            if let Some(u) = u {
                csv.serialize((s.t_min, s.sim_time_s, p, u.rss_kib, u.threads, u.fds))?;
            }
        }
    }
    csv.flush()?;
    plot(r, &dir.join("soak.png"))
}

fn plot(r: &SoakReport, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    let (w, h) = (1100u32, 800u32);
    crate::eval::plot::png(path, (w, h), |root| -> Result<()> {
        let title = format!(
            "slipstream soak: {:.0} min, {} clock, {} perception",
            r.minutes,
            r.mode.name(),
            r.perception.name()
        );
        let root = root.titled(&title, ("sans-serif", 22))?;
        let panels = root.split_evenly((2, 1));
        let t_end = r.samples.last().map_or(1.0, |s| s.t_min).max(0.1);
        let colors = [RGBColor(31, 119, 180), RGBColor(255, 127, 14), RGBColor(44, 160, 44), RGBColor(214, 39, 40)];
        /// A panel: its label and the figure it plots.
        type Panel = (&'static str, fn(&Usage) -> f64);
        let pick: [Panel; 2] = [
            ("resident memory (MB)", |u| u.rss_kib as f64 / 1024.0),
            ("threads + open files", |u| (u.threads + u.fds) as f64),
        ];
        for (panel, (label, f)) in panels.iter().zip(pick) {
            let hi = r.samples.iter().flat_map(|s| s.usage.iter().flatten().map(f)).fold(1.0f64, f64::max) * 1.15;
            let mut chart = ChartBuilder::on(panel)
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_end, 0.0..hi)?;
            chart.configure_mesh().x_desc("wall time (min)").y_desc(label).label_style(("sans-serif", 14)).draw()?;
            for (i, (name, color)) in r.processes.iter().zip(colors.iter().cycle()).enumerate() {
                let pts: Vec<(f64, f64)> =
                    r.samples.iter().filter_map(|s| s.usage[i].as_ref().map(|u| (s.t_min, f(u)))).collect();
                let color = *color;
                chart
                    .draw_series(LineSeries::new(pts, color.stroke_width(2)))?
                    .label(name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            }
            crate::eval::plot::draw_legend(&mut chart)?;
        }
        Ok(())
    })?;
    Ok(())
}

/// The report for people.
pub fn summary(r: &SoakReport) -> String {
    let mut s = format!(
        "\nsoak: {:.1} min, {} clock, {} perception: {:.0} s simulated, {} steps, lockstep timeouts {}, control timeouts {}{}\n",
        r.samples.last().map_or(0.0, |x| x.t_min),
        r.mode.name(),
        r.perception.name(),
        r.sim_time_s,
        r.steps,
        r.lockstep_timeouts,
        r.control_timeouts,
        if r.died.is_empty() { String::new() } else { format!("; DIED: {}", r.died.join(", ")) }
    );
    s.push_str(&format!(
        "  {:<22} {:>12} {:>12} {:>9} {:>13} {:>9}   (after {:.1} min of warm-up -> end)\n",
        "process", "RSS MB warm", "RSS MB end", "drift", "threads", "fds", r.warmup_minutes
    ));
    for v in &r.verdicts {
        let mb = |u: Option<Usage>| u.map_or("-".into(), |u| format!("{:.1}", u.rss_kib as f64 / 1024.0));
        let pair = |f: fn(&Usage) -> u64| match (v.warm, v.end) {
            (Some(w), Some(e)) => format!("{} -> {}", f(&w), f(&e)),
            _ => "-".into(),
        };
        s.push_str(&format!(
            "  {:<22} {:>12} {:>12} {:>8} {:>13} {:>9}   {}\n",
            v.process,
            mb(v.warm),
            mb(v.end),
            v.rss_drift.map_or("-".into(), |d| format!("{:+.1}%", d * 100.0)),
            pair(|u| u.threads),
            pair(|u| u.fds),
            if v.pass { "ok" } else { "GROWS" }
        ));
    }
    if r.garbage_sent > 0 {
        s.push_str(&format!(
            "  malformed payloads: {} published, {} counted and dropped by the ACC's and the simulator's inputs (the rest went to keys they do not read, or decoded)\n",
            r.garbage_sent, r.garbage_rejected
        ));
    }
    s.push_str(&format!(
        "  {} (aim: RSS drift < {:.0} %, no new threads or files, every step answered)\n  report: {}",
        if r.pass { "pass" } else { "FAIL" },
        RSS_DRIFT_AIM * 100.0,
        r.report_dir.join("soak.json").display()
    ));
    s
}

/// `slipstream soak`: the summary (or JSON); exit 1 when something grew or a step went
/// unanswered.
pub fn command(args: &SoakArgs, connect: &crate::config::ConnectArgs) -> Result<std::process::ExitCode> {
    let report = run(args, connect)?;
    crate::cli::print_report(args.json, &report, summary)?;
    Ok(crate::cli::exit_when(report.pass))
}
