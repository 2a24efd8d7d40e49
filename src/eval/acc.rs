//! `slipstream eval acc`: the scenario suite. For each scenario it runs the loop through the
//! launch layer ([`crate::launch::LoopRun`], the same path as `slipstream up`): slipstream-sim
//! in lockstep, slipstream-detect (camera perception only) and slipstream-acc as separate
//! processes on loopback ports and a namespace of their own ([`Network::Isolated`]), records
//! vehicle/state, acc/status, objects and sim/events from a session of its own, and judges the
//! run against the ground truth ([`super::trace::judge`], [`super::Metrics`]).
//!
//! The nodes' logs go to a directory per scenario and perception under `--logs` (default: a temporary
//! directory, removed when every scenario passed and kept, with its path printed, when not).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use super::metrics::{aims, Metrics};
use super::trace::{judge, Recorder};
use super::{fmt_opt, plot};
use crate::acc::PerceptionSource;
use crate::config::{FaultArgs, FaultProfile};
use crate::launch::{ClockMode, LoopRun, LoopSpec, Network, NodeInput, NODE_POLL};
use crate::sim::Scenario;

#[derive(Debug, Clone, clap::Args)]
pub struct EvalAccArgs {
    /// Scenarios to run (built-in names or .json5 files) [default: every built-in scenario]
    #[arg(long = "scenario", value_name = "NAME")]
    pub scenarios: Vec<String>,
    /// Where the ACC's vehicles ahead come from: camera (slipstream-detect on the rendered
    /// frames) or ground-truth (the simulator's objects)
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// Write a PNG per scenario here, <scenario>-<perception>.png (ego speed, lead speed, gap,
    /// desired gap, acceleration)
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
    /// End each scenario after this many simulated seconds instead of its own duration
    #[arg(long)]
    pub duration: Option<f64>,
    /// Wall-clock limit per scenario, seconds
    #[arg(long, default_value_t = 600.0)]
    pub timeout: f64,
    /// Keep the nodes' logs here, one directory per scenario and perception [default: a
    /// temporary directory, removed when every scenario passes]
    #[arg(long, value_name = "DIR")]
    pub logs: Option<PathBuf>,
    #[command(flatten)]
    pub faults: FaultArgs,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScenarioResult {
    pub scenario: String,
    pub perception: PerceptionSource,
    pub set_speed_mps: f64,
    pub metrics: Metrics,
    /// Steps the simulator waited out without the ACC's answer (should be 0).
    pub lockstep_timeouts: u64,
    pub end: String,
    pub wall_time_s: f64,
    pub plot: Option<PathBuf>,
    /// The fault profile the nodes injected, if any.
    pub faults: Option<String>,
    /// The ACC's and the simulator's inputs: lost on the way vs dropped by injected faults.
    pub inputs: Vec<NodeInput>,
}

#[derive(Debug, Clone, Serialize)]
pub struct AccReport {
    pub command: String,
    pub results: Vec<ScenarioResult>,
    pub pass: bool,
}

/// Runs the suite; progress goes to stderr. The nodes and the recorder use the topic config
/// of `connect` (-t, SLIPSTREAM_CONFIG or ./config/slipstream.json5) under a namespace of the
/// run's own; the connection flags do not apply (each run has its own loopback ports).
pub fn run(args: &EvalAccArgs, connect: &crate::config::ConnectArgs) -> Result<AccReport> {
    // The topic config and the fault profile are checked here, once, before any process starts.
    connect.topic_map()?;
    let faults = args.faults.profile()?;
    let names: Vec<String> = if args.scenarios.is_empty() {
        crate::sim::scenario::BUILT_IN.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let scenarios: Vec<Scenario> = names.iter().map(|n| Scenario::find(n)).collect::<Result<_, _>>()?;
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    }
    anyhow::ensure!(args.timeout > 0.0, "--timeout must be > 0");
    let logs = match &args.logs {
        Some(dir) => dir.clone(),
        None => std::env::temp_dir().join(format!("slipstream-eval-acc-{}", std::process::id())),
    };
    let rt = tokio::runtime::Runtime::new()?;
    let mut results = Vec::new();
    for (i, (arg, scenario)) in names.iter().zip(scenarios).enumerate() {
        let name = scenario.name.clone();
        eprint!("[{}/{}] {name} ({:?} perception) ... ", i + 1, names.len(), args.perception);
        let started = Instant::now();
        // Named by perception too: runs with camera and ground truth into one directory keep
        // both.
        let run_logs = logs.join(format!("{name}-{}", args.perception.name()));
        let result = rt
            .block_on(run_one(arg, scenario, args, faults.clone(), connect.topics.as_deref(), &run_logs))
            .with_context(|| format!("scenario {name} (node logs in {})", run_logs.display()))?;
        eprintln!(
            "{} in {:.1} s{}",
            if result.metrics.pass { "pass" } else { "FAIL" },
            started.elapsed().as_secs_f64(),
            result.plot.as_ref().map_or(String::new(), |p| format!(", plot {}", p.display()))
        );
        results.push(result);
    }
    let pass = results.iter().all(|r| r.metrics.pass && r.lockstep_timeouts == 0);
    if pass && args.logs.is_none() {
        let _ = std::fs::remove_dir_all(&logs);
    } else {
        eprintln!("node logs: {}", logs.display());
    }
    Ok(AccReport { command: std::env::args().collect::<Vec<_>>().join(" "), results, pass })
}

/// One scenario through the launch layer, judged; `faults` injected by every node.
pub(crate) async fn run_one(
    scenario_arg: &str,
    mut scenario: Scenario,
    args: &EvalAccArgs,
    faults: Option<FaultProfile>,
    topics_file: Option<&Path>,
    logs: &Path,
) -> Result<ScenarioResult> {
    if let Some(d) = args.duration {
        anyhow::ensure!(d > 0.0, "--duration must be > 0");
        scenario.duration_s = d;
    }
    let name = scenario.name.clone();
    let set_speed = scenario.ego.controller_set_speed_mps();
    let spec = LoopSpec {
        scenario: scenario_arg.to_string(),
        duration_s: scenario.duration_s,
        clock: ClockMode::Lockstep,
        perception: args.perception,
        set_speed_mps: set_speed,
        time_gap_s: scenario.ego.time_gap_s,
        faults,
    };
    let faults = spec.faults.as_ref().map(|p| p.summary());
    // A namespace and ports of this run's own: nothing else on the machine is disturbed.
    let namespace =
        format!("eval-acc-{}-{}", std::process::id(), name.replace(|c: char| !c.is_ascii_alphanumeric(), "-"));
    let network = Network::Isolated { topics: topics_file.map(Path::to_path_buf), namespace };
    let mut lp = LoopRun::open(spec, network, logs, "eval-acc").await?;
    let recorder = Recorder::start(lp.bus()).await?;
    let started = Instant::now();
    lp.start().await?;
    let timeout = Duration::from_secs_f64(args.timeout);
    let progress = loop {
        let progress = lp.check();
        if progress.over() || started.elapsed() > timeout {
            break progress;
        }
        tokio::time::sleep(NODE_POLL).await;
    };
    let wall = started.elapsed().as_secs_f64();
    lp.stop().await;
    let rec = recorder.take();
    drop(recorder);
    let sim = lp.sim_report();
    let inputs = lp.inputs();
    lp.close().await;
    if progress.sim_ended.is_none() && progress.died.is_empty() {
        bail!("slipstream-sim did not finish within {} s (--timeout)", args.timeout);
    }
    anyhow::ensure!(progress.died.is_empty(), "{} ended before the run was over", progress.died.join(", "));
    let sim = sim?;

    let judged = judge(&rec, &scenario, Some(&sim), "stopped");
    let trace = judged.trace;
    let metrics = judged
        .metrics
        .with_context(|| format!("recorded only {} states (did the nodes connect?)", trace.samples.len()))?;
    let plot = match &args.plots {
        Some(dir) => {
            let path = dir.join(format!("{name}-{}.png", args.perception.name()));
            let title =
                format!("{name} ({:?} perception): {}", args.perception, if metrics.pass { "pass" } else { "FAIL" });
            plot::plot(&trace, &title, &path)?;
            Some(path)
        }
        None => None,
    };
    Ok(ScenarioResult {
        scenario: name,
        perception: args.perception,
        set_speed_mps: set_speed,
        metrics,
        lockstep_timeouts: sim.lockstep_timeouts,
        end: trace.end.clone(),
        wall_time_s: wall,
        plot,
        faults,
        inputs,
    })
}

/// The report as a markdown table.
pub fn markdown(report: &AccReport) -> String {
    let mut out = String::new();
    out.push_str("| scenario | perception | collisions (traffic) | min gap m | min TTC s | time-gap RMS s | speed RMSE m/s | max accel | max decel | max jerk | accel swing | hard-braking answer s | emergency s (unwarranted) | phantom braking s | stopped for nothing s | result |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &report.results {
        let m = &r.metrics;
        let failed: Vec<&str> = m.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect();
        let verdict = if m.pass && r.lockstep_timeouts == 0 {
            "pass".to_string()
        } else if r.lockstep_timeouts > 0 {
            format!("FAIL: {} lockstep timeouts {}", r.lockstep_timeouts, failed.join(", "))
        } else {
            format!("FAIL: {}", failed.join(", "))
        };
        let [gap, ttc, time_gap, speed, accel, decel, jerk] = m.headline();
        out.push_str(&format!(
            "| {} | {:?} | {} ({}) | {gap} | {ttc} | {time_gap} | {speed} | {accel} | {decel} | {jerk} | {} | {} | {:.1} ({}) | {:.1} | {:.1} | {} |\n",
            r.scenario,
            r.perception,
            m.collisions,
            m.traffic_collisions,
            fmt_opt(m.max_accel_swing_mps2, 2),
            fmt_opt(m.hard_braking_response_s, 2),
            m.emergency_s,
            m.unwarranted_emergencies,
            m.phantom_braking_s,
            m.standstill_for_nothing_s,
            verdict
        ));
    }
    out.push_str(&format!(
        "\nAims: no collision; in steady following time-gap RMS error <= {} s and acceleration within {} m/s2 of the lead's; a scenario's own minimum gap (expect.min_gap_m); accel <= {}, decel <= {} m/s2 (+{:.0}% tolerance) and jerk <= {} m/s3 outside emergencies, at speed; no unwarranted emergency, no phantom braking (beyond 1 m/s2 with nothing in the lane within twice the time gap), no standstill with nothing ahead. Traffic collisions and the answer to a lead braking beyond the comfort limit (until the ACC asks for 90% of what stopping behind it needs; aim {} s) are reported, not judged.\n",
        aims::TIME_GAP_RMS_S,
        aims::MAX_ACCEL_SWING_MPS2,
        aims::MAX_ACCEL_MPS2,
        aims::MAX_DECEL_MPS2,
        aims::COMFORT_TOLERANCE * 100.0,
        aims::MAX_JERK_MPS3,
        aims::HARD_BRAKING_RESPONSE_S,
    ));
    out
}
