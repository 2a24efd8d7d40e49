//! `slipstream eval acc`: the scenario suite. For each scenario it runs the loop through the
//! launch layer ([`slipstream_launch::LoopRun`], the same path as `slipstream up`): slipstream-sim
//! in lockstep, slipstream-detect (camera perception only) and slipstream-acc as separate
//! processes on loopback ports and a namespace of their own ([`Network::Isolated`]), records
//! vehicle/state, acc/status, objects and sim/events from a session of its own, and judges the
//! run against the ground truth ([`super::judge::judge`], [`super::Metrics`]).
//!
//! The nodes' logs go to a directory per scenario and perception under `--logs` (default: a temporary
//! directory, removed when every scenario passed and kept, with its path printed, when not).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use serde::Serialize;

use super::metrics::{aims, Metrics};
use super::{fmt_opt, plot};
use slipstream_acc::PerceptionSource;
use slipstream_contract::config::{FaultArgs, FaultProfile};
use slipstream_launch::{ClockMode, LinkKind, LoopRun, LoopSpec, Network, OwnNodeArgs, OwnNodes, NODE_POLL};
use slipstream_observe::NodeInput;
use slipstream_sim::{Scenario, SimTime};

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
    /// Scenarios run at once, each loop in its own processes, ports and namespace (lockstep
    /// runs are the same whatever runs beside them) [default: the CPU cores, at most 4]
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// How the loop's processes reach each other (to compare the two)
    #[arg(long, value_enum, default_value = "unix")]
    pub link: LinkKind,
    #[command(flatten)]
    pub faults: FaultArgs,
    #[command(flatten)]
    pub own: OwnNodeArgs,
}

#[derive(Debug, Clone, Serialize, serde::Deserialize)]
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
    /// The ACC's and the simulator's inputs (lost on the way vs dropped by injected faults),
    /// and the observer's: what the run is judged by.
    pub inputs: Vec<NodeInput>,
    /// Where the run's wall time went.
    pub time: RunTime,
    /// Nodes their restart policy started again, and how often (a loop file's `restart`).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub restarts: std::collections::BTreeMap<String, u32>,
    /// With several controlled vehicles, each one judged on its own topics (`metrics` is then
    /// the first's); the scenario passes when every one does.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub egos: Vec<super::egos::EgoResult>,
}

impl ScenarioResult {
    /// Passed: every check, and every step answered in time.
    pub fn passed(&self) -> bool {
        self.metrics.pass && self.lockstep_timeouts == 0 && self.egos.iter().all(super::egos::EgoResult::passed)
    }

    /// A result with these metrics and nothing else to say (the sweep's unit tests).
    #[cfg(test)]
    pub(crate) fn for_tests(name: &str, metrics: Metrics) -> ScenarioResult {
        ScenarioResult {
            scenario: name.into(),
            perception: PerceptionSource::Camera,
            set_speed_mps: 25.0,
            metrics,
            lockstep_timeouts: 0,
            end: "duration".into(),
            wall_time_s: 1.0,
            plot: None,
            faults: None,
            inputs: Vec::new(),
            time: RunTime::default(),
            restarts: Default::default(),
            egos: Vec::new(),
        }
    }
}

/// Where one run's wall time went, in seconds.
#[derive(Debug, Clone, Copy, Default, Serialize, serde::Deserialize)]
pub struct RunTime {
    /// Simulated time.
    pub simulated_s: f64,
    /// The whole run: joining the bus, starting the nodes, the simulation, stopping them.
    pub wall_s: f64,
    /// The simulator's own run, first step to last.
    pub sim_wall_s: f64,
    /// The simulator's shares of `sim_wall_s`.
    pub sim: SimTime,
    /// The detector computing (camera perception), inside the simulator's wait for answers.
    pub detect_busy_s: f64,
    /// The ACC computing its answers, inside the simulator's wait.
    pub acc_busy_s: f64,
}

impl RunTime {
    /// Starting and stopping the processes: the run less the simulator's own run.
    pub(crate) fn start_stop_s(&self) -> f64 {
        (self.wall_s - self.sim_wall_s).max(0.0)
    }

    /// What the simulator waited for that no node spent computing: the messages' way through
    /// the transport, the nodes' wake-ups and the ACC's wait for the detections.
    pub(crate) fn transport_s(&self) -> f64 {
        (self.sim.awaiting_s - self.detect_busy_s - self.acc_busy_s).max(0.0)
    }

    fn add(&mut self, o: &RunTime) {
        self.simulated_s += o.simulated_s;
        self.wall_s += o.wall_s;
        self.sim_wall_s += o.sim_wall_s;
        self.sim.physics_s += o.sim.physics_s;
        self.sim.render_s += o.sim.render_s;
        self.sim.publish_s += o.sim.publish_s;
        self.sim.awaiting_s += o.sim.awaiting_s;
        self.sim.pacing_s += o.sim.pacing_s;
        self.detect_busy_s += o.detect_busy_s;
        self.acc_busy_s += o.acc_busy_s;
    }
}

/// Scenarios run at once when --jobs is not given: one per core, at most this many (each
/// loop holds shared-memory pools for its cameras).
pub(crate) const MAX_DEFAULT_JOBS: usize = 4;

#[derive(Debug, Clone, Serialize)]
pub struct AccReport {
    pub command: String,
    /// The nodes of the user's own it judged (their command and files by content); empty: ours.
    pub own: OwnNodes,
    pub results: Vec<ScenarioResult>,
    /// Scenarios that did not finish (a node died, a timeout, too little to judge): not
    /// judged, and the suite does not pass.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unfinished: Vec<Unfinished>,
    pub pass: bool,
    /// Scenarios run at once.
    pub jobs: usize,
    /// The suite's wall time, seconds.
    pub wall_s: f64,
}

/// A scenario of the suite that did not finish, and why: the node that died with its exit
/// and last words, a timeout, a run too short to judge.
#[derive(Debug, Clone, Serialize)]
pub struct Unfinished {
    pub scenario: String,
    pub error: String,
}

/// Runs at once: `--jobs`, else one per CPU core, at most [`MAX_DEFAULT_JOBS`].
pub(crate) fn jobs(arg: Option<usize>) -> Result<usize> {
    match arg {
        Some(0) => Err(Error::flag("--jobs", "must be at least 1")),
        Some(n) => Ok(n),
        None => Ok(std::thread::available_parallelism().map_or(1, |n| n.get()).min(MAX_DEFAULT_JOBS)),
    }
}

/// Runs the suite; progress goes to stderr. The nodes and the recorder use the topic config
/// of `connect` (-t, SLIPSTREAM_CONFIG or ./config/slipstream.json5) under a namespace of the
/// run's own; the connection flags do not apply (each run has its own loopback ports).
pub fn run(args: &EvalAccArgs, connect: &slipstream_contract::config::ConnectArgs) -> Result<AccReport> {
    // The topic config and the fault profile are checked here, once, before any process starts.
    connect.topic_map()?;
    let faults = args.faults.profile()?;
    let own = args.own.nodes_started_here()?;
    let names: Vec<String> = if args.scenarios.is_empty() {
        slipstream_sim::scenario::BUILT_IN.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let scenarios: Vec<Scenario> = names.iter().map(|n| Scenario::find(n)).collect::<Result<_, _>>()?;
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).map_err(Error::file("create", dir))?;
    }
    if args.timeout <= 0.0 || args.timeout.is_nan() {
        return Err(Error::flag("--timeout", "must be > 0"));
    }
    let logs = match &args.logs {
        Some(dir) => dir.clone(),
        None => std::env::temp_dir().join(format!("slipstream-eval-acc-{}", std::process::id())),
    };
    let jobs = jobs(args.jobs)?.min(names.len().max(1));
    let suite_started = Instant::now();
    let runs: Vec<(String, Scenario)> = names.iter().cloned().zip(scenarios).collect();
    let total = runs.len();
    let perception = args.perception;
    let under = Under { faults, own: own.clone() };
    let results =
        run_all(runs, args, &under, connect.topics.clone(), &logs, jobs, |done, name, result| match result {
            Ok(r) => eprintln!(
                "[{done}/{total}] {name} ({} perception): {} in {:.1} s ({:.0} s simulated){}",
                perception.name(),
                if r.passed() { "pass" } else { "FAIL" },
                r.time.wall_s,
                r.time.simulated_s,
                r.plot.as_ref().map_or(String::new(), |p| format!(", plot {}", p.display()))
            ),
            Err(e) => {
                eprintln!("[{done}/{total}] {name} ({} perception): did not finish: {}", perception.name(), e.chain())
            }
        })?;
    let (results, unfinished) = finished_or_not(results)?;
    let wall_s = suite_started.elapsed().as_secs_f64();
    let pass = unfinished.is_empty() && results.iter().all(ScenarioResult::passed);
    if pass && args.logs.is_none() {
        let _ = std::fs::remove_dir_all(&logs);
    } else {
        eprintln!("node logs: {}", logs.display());
    }
    Ok(AccReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        own,
        results,
        unfinished,
        pass,
        jobs,
        wall_s,
    })
}

/// The runs that finished, and those that did not with their reasons. A suite none of whose
/// runs finished is an error of its own (a controller that never starts, a bad settings file):
/// the first run's error, as it is.
fn finished_or_not(results: Vec<Result<ScenarioResult>>) -> Result<(Vec<ScenarioResult>, Vec<Unfinished>)> {
    if !results.is_empty() && results.iter().all(Result::is_err) {
        return Err(results.into_iter().find_map(Result::err).expect("every result is an error"));
    }
    let (mut finished, mut unfinished) = (Vec::new(), Vec::new());
    for r in results {
        match r {
            Ok(r) => finished.push(r),
            Err(Error::Run { run, source, logs }) => {
                let scenario = run.strip_prefix("scenario ").unwrap_or(&run).to_string();
                let error = format!("{} (node logs in {})", source.chain(), logs.display());
                unfinished.push(Unfinished { scenario, error });
            }
            Err(e) => return Err(e),
        }
    }
    Ok((finished, unfinished))
}

/// Runs each of `runs` (the simulator's `--scenario` argument: a built-in name or a file, and
/// the scenario it names) through [`run_one`], `jobs` at once, each in its own processes,
/// ports and namespace; its logs in `logs/<scenario>-<perception>`. `done` hears of each as it
/// ends (how many have, its name, its result). The results in the order of `runs`; one run's
/// failure does not stop the others.
pub(crate) fn run_all(
    runs: Vec<(String, Scenario)>,
    args: &EvalAccArgs,
    under: &Under,
    topics: Option<PathBuf>,
    logs: &Path,
    jobs: usize,
    mut done: impl FnMut(usize, &str, &Result<ScenarioResult>),
) -> Result<Vec<Result<ScenarioResult>>> {
    let total = runs.len();
    let rt = tokio::runtime::Runtime::new().map_err(Error::system("start the async runtime"))?;
    rt.block_on(async {
        let slots = std::sync::Arc::new(tokio::sync::Semaphore::new(jobs.max(1)));
        let mut running = tokio::task::JoinSet::new();
        for (i, (arg, scenario)) in runs.into_iter().enumerate() {
            let (args, under, topics) = (args.clone(), under.clone(), topics.clone());
            // Named by perception too: runs with camera and ground truth into one directory
            // keep both.
            let run_logs = logs.join(format!("{}-{}", scenario.name, args.perception.name()));
            let slots = slots.clone();
            running.spawn(async move {
                let _slot = slots.acquire_owned().await.expect("the semaphore is never closed");
                let name = scenario.name.clone();
                let result = run_one(&arg, scenario, &args, under, topics.as_deref(), &run_logs)
                    .await
                    .map_err(|e| Error::Run { run: format!("scenario {name}"), logs: run_logs, source: Box::new(e) });
                (i, name, result)
            });
        }
        let mut results: Vec<Option<Result<ScenarioResult>>> = (0..total).map(|_| None).collect();
        let mut finished = 0;
        while let Some(joined) = running.join_next().await {
            let (i, name, result) = joined?;
            finished += 1;
            done(finished, &name, &result);
            results[i] = Some(result);
        }
        Ok(results.into_iter().flatten().collect())
    })
}

/// Whether the run ended as a run should: the simulator finished within `timeout_s` and no
/// node died before it.
fn ended_in_time(
    progress: &slipstream_launch::Progress,
    ends: &[slipstream_launch::NodeEnd],
    timeout_s: f64,
) -> Result<()> {
    if progress.sim_ended.is_none() && progress.died.is_empty() {
        let problem = format!("did not finish within {timeout_s} s (--timeout)");
        return Err(Error::node("slipstream-sim", problem));
    }
    if let Some(first) = progress.died.first() {
        let end = ends.iter().find(|e| &e.node == first);
        let code = end.and_then(|e| e.exit_code).map_or("killed by a signal".into(), |c| format!("exit code {c}"));
        let said = end.and_then(slipstream_launch::NodeEnd::why).map_or(String::new(), |w| format!(": {w}"));
        return Err(Error::node(progress.died.join(", "), format!("ended before the run was over ({code}){said}")));
    }
    Ok(())
}

/// A run too short to judge: what the observer received of each topic the judge reads (a
/// controller that answers every step but publishes no acc/status shows as such), and how
/// the simulator ended it.
fn unjudged(states: usize, sim: &slipstream_sim::SimReport, inputs: &[NodeInput]) -> Error {
    let ended = sim.end.as_ref().filter(|e| !e.success);
    let ended = ended.map_or(String::new(), |e| format!("; the simulator ended: {}", e.reason));
    let seen: Vec<String> = inputs
        .iter()
        .filter(|i| i.node == "observer")
        .map(|i| format!("{} {}", i.stats.received, i.stats.topic))
        .collect();
    let seen = match seen.is_empty() {
        true => "(did the nodes connect?)".to_string(),
        false => format!(
            "(the observer received {}; a run is judged on vehicle/state and the controller's acc/status, docs/node-contract.md)",
            seen.join(", ")
        ),
    };
    Error::Unjudged(format!("recorded only {states} states to judge {seen}{ended}"))
}

/// What every run of a suite puts under test besides the scenario, parsed once for the suite:
/// the faults its nodes inject, and the nodes of the user's own in the place of ours.
#[derive(Debug, Clone, Default)]
pub(crate) struct Under {
    pub(crate) faults: Option<FaultProfile>,
    pub(crate) own: OwnNodes,
}

/// One scenario through the launch layer, judged, `under` what it names.
pub(crate) async fn run_one(
    scenario_arg: &str,
    mut scenario: Scenario,
    args: &EvalAccArgs,
    under: Under,
    topics_file: Option<&Path>,
    logs: &Path,
) -> Result<ScenarioResult> {
    if let Some(d) = args.duration {
        if d <= 0.0 || d.is_nan() {
            return Err(Error::flag("--duration", "must be > 0"));
        }
        scenario.duration_s = d;
    }
    let name = scenario.name.clone();
    let set_speed = scenario.ego().controller_set_speed_mps();
    let spec = LoopSpec {
        scenario: scenario_arg.to_string(),
        duration_s: scenario.duration_s,
        clock: ClockMode::Lockstep,
        perception: args.perception,
        set_speed_mps: set_speed,
        time_gap_s: scenario.ego().time_gap_s,
        vehicle: Some(LoopSpec::vehicle_of(&scenario)),
        faults: under.faults,
        link: args.link,
        own: under.own,
        egos: slipstream_launch::EgoNodes::of(&scenario),
    };
    let faults = spec.faults.as_ref().map(|p| p.summary());
    // A namespace and ports of this run's own: nothing else on the machine is disturbed.
    let namespace =
        format!("eval-acc-{}-{}", std::process::id(), name.replace(|c: char| !c.is_ascii_alphanumeric(), "-"));
    let network = Network::Isolated { topics: topics_file.map(Path::to_path_buf), namespace };
    let opened = Instant::now();
    let mut lp = LoopRun::open(spec, network, logs, "eval-acc").await?;
    let recorders = super::egos::record_each(&lp).await?;
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
    let ends = lp.stop().await;
    let recorded: Vec<_> = recorders.iter().map(|(ns, r)| (ns.clone(), r.take())).collect();
    let sim = lp.sim_report();
    let mut inputs = lp.inputs();
    let observed = recorders.first().map(|(_, r)| r.inputs()).unwrap_or_default();
    inputs.extend(observed.into_iter().map(|stats| NodeInput { node: "observer".into(), stats }));
    drop(recorders);
    let (acc_busy_s, detect_busy_s) =
        (lp.acc_report().map_or(0.0, |a| a.busy_s), lp.detect_report().ok().flatten().map_or(0.0, |d| d.busy_s));
    lp.close().await;
    let wall_s = opened.elapsed().as_secs_f64();
    ended_in_time(&progress, &ends, args.timeout)?;
    let sim = sim?;
    let time = RunTime {
        simulated_s: sim.sim_time_s,
        wall_s,
        sim_wall_s: sim.wall_time_s,
        sim: sim.time,
        detect_busy_s,
        acc_busy_s,
    };
    let mut judged = super::egos::judge_all(&recorded, &scenario, &sim);
    let egos = super::egos::results(&recorded, &judged, &sim)?;
    let judged = judged.swap_remove(0);
    let trace = judged.trace;
    let metrics = judged.metrics.ok_or_else(|| unjudged(trace.samples.len(), &sim, &inputs))?;
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
        time,
        restarts: ends.iter().filter(|e| e.restarts > 0).map(|e| (e.node.clone(), e.restarts)).collect(),
        egos,
    })
}

/// "pass", or what failed.
fn verdict(passed: bool, m: &Metrics, lockstep_timeouts: u64) -> String {
    let failed: Vec<&str> = m.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect();
    if passed {
        "pass".to_string()
    } else if lockstep_timeouts > 0 {
        format!("FAIL: {lockstep_timeouts} lockstep timeouts {}", failed.join(", "))
    } else {
        format!("FAIL: {}", failed.join(", "))
    }
}

/// One row of the table: a scenario's run, or one car's in a scenario with several.
fn row(name: &str, perception: PerceptionSource, m: &Metrics, verdict: &str) -> String {
    let [gap, ttc, time_gap, speed, accel, decel, jerk] = m.headline();
    format!(
        "| {name} | {perception:?} | {} ({}) | {gap} | {ttc} | {time_gap} | {speed} | {accel} | {decel} | {jerk} | {} | {} | {:.1} ({}) | {:.1} | {:.1} | {verdict} |\n",
        m.collisions,
        m.traffic_collisions,
        fmt_opt(m.max_accel_swing_mps2, 2),
        fmt_opt(m.hard_braking_response_s, 2),
        m.emergency_s,
        m.unwarranted_emergencies,
        m.phantom_braking_s,
        m.standstill_for_nothing_s,
    )
}

/// The report as a markdown table.
pub fn markdown(report: &AccReport) -> String {
    let mut out = String::new();
    out.push_str("| scenario | perception | collisions (traffic) | min gap m | min TTC s | time-gap RMS s | speed RMSE m/s | max accel | max decel | max jerk | accel swing | hard-braking answer s | emergency s (unwarranted) | phantom braking s | stopped for nothing s | result |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &report.results {
        let restarted: Vec<String> = r.restarts.iter().map(|(n, k)| format!("{n} restarted {k}x")).collect();
        let with_restarts = |verdict: String| match restarted.is_empty() {
            true => verdict,
            false => format!("{verdict} ({})", restarted.join(", ")),
        };
        if r.egos.is_empty() {
            let verdict = with_restarts(verdict(r.passed(), &r.metrics, r.lockstep_timeouts));
            out.push_str(&row(&r.scenario, r.perception, &r.metrics, &verdict));
        }
        for e in &r.egos {
            let verdict = with_restarts(verdict(e.passed(), &e.metrics, e.lockstep_timeouts));
            out.push_str(&row(&format!("{} {}", r.scenario, e.namespace), r.perception, &e.metrics, &verdict));
        }
    }
    for u in &report.unfinished {
        out.push_str(&format!(
            "| {} |{} did not finish: {} |\n",
            u.scenario,
            " - |".repeat(14),
            u.error.replace('|', "/")
        ));
    }
    out.push_str(&format!(
        "\nAims: no collision; in steady following time-gap RMS error <= {} s and acceleration within {} m/s2 of the lead's; a scenario's own minimum gap (expect.min_gap_m); accel <= {}, decel <= {} m/s2 at {} m/s and above rising to {} at {} m/s and below (+{:.0}% tolerance) and jerk <= {} m/s3 outside emergencies, at speed; no unwarranted emergency, no phantom braking (beyond 1 m/s2 with nothing in the lane within twice the time gap), no standstill with nothing ahead. Traffic collisions and the answer to a lead braking beyond the comfort limit (until the ACC asks for 90% of what stopping behind it needs; aim {} s) are reported, not judged.\n",
        aims::TIME_GAP_RMS_S,
        aims::MAX_ACCEL_SWING_MPS2,
        aims::MAX_ACCEL_MPS2,
        aims::MAX_DECEL_MPS2,
        slipstream_acc::settings::COMFORT_HIGH_SPEED_MPS,
        aims::MAX_DECEL_LOW_SPEED_MPS2,
        slipstream_acc::settings::COMFORT_LOW_SPEED_MPS,
        aims::COMFORT_TOLERANCE * 100.0,
        aims::MAX_JERK_MPS3,
        aims::HARD_BRAKING_RESPONSE_S,
    ));
    out.push('\n');
    out.push_str(&time_table(report));
    out
}

/// Where the suite's time went: the runs' wall time summed, split by what the processes did.
pub(crate) fn time_table(report: &AccReport) -> String {
    let mut t = RunTime::default();
    for r in &report.results {
        t.add(&r.time);
    }
    let rtf = |wall: f64| if wall > 0.0 { t.simulated_s / wall } else { 0.0 };
    let share = |x: f64| if t.wall_s > 0.0 { 100.0 * x / t.wall_s } else { 0.0 };
    let mut out = format!(
        "Time: {:.0} s simulated in {:.1} s with {} scenario(s) at once: **{:.1}x real time** ({:.1}x per run, {:.1}x inside the simulator). Where each run's time went, summed over the runs ({:.1} s):\n\n| share | s | % |\n|---|---|---|\n",
        t.simulated_s,
        report.wall_s,
        report.jobs,
        rtf(report.wall_s),
        rtf(t.wall_s),
        rtf(t.sim_wall_s),
        t.wall_s,
    );
    // A node of the user's own reports no busy time: its computing is in the waiting row.
    let (detect, acc, waiting) = match (&report.own.detector, &report.own.controller) {
        (None, None) => ("(slipstream-detect)", "(slipstream-acc)", "(the simulator waiting, no node computing)"),
        _ => (
            "(slipstream-detect; yours: in the row below)",
            "(slipstream-acc; yours: in the row below)",
            "(the simulator waiting: yours computing, or no node)",
        ),
    };
    let rows = [
        ("starting and stopping the processes (and joining the bus)".to_string(), t.start_stop_s()),
        ("physics (drivers, vehicle model, rapier)".into(), t.sim.physics_s),
        ("rendering the cameras, with the ground truth".into(), t.sim.render_s),
        ("publishing speed, state, clock, objects".into(), t.sim.publish_s),
        (format!("detecting, fusing, tracking {detect}"), t.detect_busy_s),
        (format!("the ACC computing {acc}"), t.acc_busy_s),
        (format!("transport and wake-ups {waiting}"), t.transport_s()),
        ("pacing (the simulator yielding)".into(), t.sim.pacing_s),
    ];
    for (what, s) in rows {
        out.push_str(&format!("| {what} | {s:.2} | {:.1} |\n", share(s)));
    }
    out
}
