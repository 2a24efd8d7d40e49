//! `slipstream eval acc`: the scenario suite. For each scenario it starts slipstream-sim
//! (lockstep, fast), slipstream-detect (camera perception only) and slipstream-acc as separate
//! processes on loopback ports of their own and a namespace of their own, records vehicle/state,
//! acc/status, objects and sim/events from a session of its own, and judges the run against the
//! ground truth ([`super::eval::Metrics`]).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use parking_lot::Mutex;
use serde::Serialize;

use super::eval::{truth_lead, Metrics, Sample, Trace};
use super::settings::PerceptionSource;
use crate::bus::Received;
use crate::msg::{AccStatus, GroundTruthObjects, SimEvent, SimEventKind, VehicleState};
use crate::sim::vehicle::VehicleParams;
use crate::sim::Scenario;
use crate::tools::children::{free_ports, sibling_binary, Child};
use crate::topics;

#[derive(Debug, Clone, clap::Args)]
pub struct EvalAccArgs {
    /// Scenarios to run (built-in names or .json5 files) [default: every built-in scenario]
    #[arg(long = "scenario", value_name = "NAME")]
    pub scenarios: Vec<String>,
    /// Where the ACC's vehicles ahead come from: camera (slipstream-detect on the rendered
    /// frames) or ground-truth (the simulator's objects)
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// Write a PNG per scenario here (ego speed, lead speed, gap, desired gap, acceleration)
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
}

#[derive(Debug, Clone, Serialize)]
pub struct AccReport {
    pub command: String,
    pub results: Vec<ScenarioResult>,
    pub pass: bool,
}

/// What the recorder keeps, in arrival order.
#[derive(Default)]
pub(crate) struct Recorded {
    pub states: Vec<Received<VehicleState>>,
    pub statuses: Vec<Received<AccStatus>>,
    pub objects: Vec<Received<GroundTruthObjects>>,
    pub collisions: u64,
}

/// Records vehicle/state, acc/status, objects and the collisions on sim/events: what a run is
/// judged by.
pub(crate) struct Recorder {
    pub rec: Arc<Mutex<Recorded>>,
    _subs: [crate::bus::CallbackSubscriber; 4],
}

impl Recorder {
    pub(crate) async fn start(bus: &crate::Bus) -> Result<Recorder> {
        let rec = Arc::new(Mutex::new(Recorded::default()));
        let r = rec.clone();
        let s1 = bus.subscribe_with(topics::VEHICLE_STATE, move |m| r.lock().states.push(m)).await?;
        let r = rec.clone();
        let s2 = bus.subscribe_with(topics::ACC_STATUS, move |m| r.lock().statuses.push(m)).await?;
        let r = rec.clone();
        let s3 = bus.subscribe_with(topics::OBJECTS, move |m| r.lock().objects.push(m)).await?;
        let r = rec.clone();
        let s4 = bus
            .subscribe_with(topics::SIM_EVENTS, move |m: Received<SimEvent>| {
                if matches!(m.msg.kind, SimEventKind::Collision { .. }) {
                    r.lock().collisions += 1;
                }
            })
            .await?;
        Ok(Recorder { rec, _subs: [s1, s2, s3, s4] })
    }

    /// Everything recorded so far, leaving the recorder empty.
    pub(crate) fn take(&self) -> Recorded {
        std::mem::take(&mut *self.rec.lock())
    }
}

/// Runs the suite; progress goes to stderr. The nodes and the recorder use the topic config
/// of `connect` (-t, SLIPSTREAM_CONFIG or ./config/slipstream.json5) under a namespace of the
/// run's own; the connection flags do not apply (each run has its own loopback ports).
pub fn run(args: &EvalAccArgs, connect: &crate::config::ConnectArgs) -> Result<AccReport> {
    let topic_map = connect.topic_map()?;
    let names: Vec<String> = if args.scenarios.is_empty() {
        crate::sim::scenario::BUILT_IN.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let scenarios: Vec<Scenario> = names.iter().map(|n| Scenario::find(n)).collect::<Result<_, _>>()?;
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).with_context(|| format!("create {}", dir.display()))?;
    }
    let rt = tokio::runtime::Runtime::new()?;
    let mut results = Vec::new();
    for (i, (arg, scenario)) in names.iter().zip(scenarios).enumerate() {
        let name = scenario.name.clone();
        eprint!("[{}/{}] {name} ({:?} perception) ... ", i + 1, names.len(), args.perception);
        let started = Instant::now();
        let result = rt
            .block_on(run_one(arg, scenario, args, &topic_map, connect.topics.as_deref()))
            .with_context(|| format!("scenario {name}"))?;
        eprintln!(
            "{} in {:.1} s{}",
            if result.metrics.pass { "pass" } else { "FAIL" },
            started.elapsed().as_secs_f64(),
            result.plot.as_ref().map_or(String::new(), |p| format!(", plot {}", p.display()))
        );
        results.push(result);
    }
    let pass = results.iter().all(|r| r.metrics.pass && r.lockstep_timeouts == 0);
    Ok(AccReport { command: std::env::args().collect::<Vec<_>>().join(" "), results, pass })
}

async fn run_one(
    scenario_arg: &str,
    mut scenario: Scenario,
    args: &EvalAccArgs,
    topic_map: &crate::TopicMap,
    topics_file: Option<&std::path::Path>,
) -> Result<ScenarioResult> {
    if let Some(d) = args.duration {
        anyhow::ensure!(d > 0.0, "--duration must be > 0");
        scenario.duration_s = d;
    }
    let name = scenario.name.clone();
    let set_speed = scenario.ego.set_speed_mps.unwrap_or(scenario.ego.speed_mps);
    let ego = VehicleParams::of_class(scenario.ego.class.into());
    let ego_front = ego.size_m[0] - ego.rear_overhang_m;
    // A namespace and ports of this run's own: nothing else on the machine is disturbed.
    let namespace =
        format!("eval-acc-{}-{}", std::process::id(), name.replace(|c: char| !c.is_ascii_alphanumeric(), "-"));
    let [p_rec, p_sim, p_det, p_acc] = free_ports::<4>()?;
    let ep = |p: u16| format!("tcp/127.0.0.1:{p}");

    // The recorder: its own session, listening for the nodes.
    let mut cfg = zenoh::Config::from_json5(crate::config::DEFAULT_ZENOH_CONFIG).map_err(anyhow::Error::msg)?;
    cfg.insert_json5("listen/endpoints", &format!("[\"{}\"]", ep(p_rec))).map_err(anyhow::Error::msg)?;
    cfg.insert_json5("connect/endpoints", "[]").map_err(anyhow::Error::msg)?;
    let topics = topic_map.clone().with_namespace(&namespace)?;
    let bus = crate::Bus::open(cfg, topics, "eval-acc").await?;
    let recorder = Recorder::start(&bus).await?;

    let common = |cmd: &mut Command, listen: u16, connect: &[u16]| {
        cmd.args(["-n", &namespace, "-l", &ep(listen)]);
        if let Some(file) = topics_file {
            cmd.arg("-t").arg(file);
        }
        for p in connect {
            cmd.args(["-e", &ep(*p)]);
        }
        cmd.stdin(Stdio::null());
        // The nodes' warnings show; their chatter does not (RUST_LOG set by the user wins).
        if std::env::var_os("RUST_LOG").is_none() {
            cmd.env("RUST_LOG", "warn");
        }
    };
    let camera = args.perception == PerceptionSource::Camera;
    let mut nodes = Vec::new();
    let mut acc_cmd = Command::new(sibling_binary("slipstream-acc")?);
    acc_cmd.args(["--lockstep", "--set-speed", &set_speed.to_string()]);
    acc_cmd.args(["--perception", if camera { "camera" } else { "ground-truth" }]);
    common(&mut acc_cmd, p_acc, &[p_rec]);
    acc_cmd.stdout(Stdio::null());
    nodes.push(Child::spawn("slipstream-acc", &mut acc_cmd)?);
    if camera {
        let mut det = Command::new(sibling_binary("slipstream-detect")?);
        common(&mut det, p_det, &[p_rec, p_acc]);
        det.stdout(Stdio::null());
        nodes.push(Child::spawn("slipstream-detect", &mut det)?);
    }
    // The simulator's first frame must find the detector (and the ACC) listening.
    let wanted: Vec<&str> = if camera { vec!["acc", "detect"] } else { vec!["acc"] };
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let alive = bus.nodes_alive().await?;
        if wanted.iter().all(|w| alive.iter().any(|a| a == w)) {
            break;
        }
        for n in &mut nodes {
            if let Some(status) = n.exited() {
                bail!("{} exited at start ({status}); run it alone to see why", n.name);
            }
        }
        anyhow::ensure!(Instant::now() < deadline, "{wanted:?} not all up after 20 s (alive: {alive:?})");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let mut sim_cmd = Command::new(sibling_binary("slipstream-sim")?);
    sim_cmd.args(["--scenario", scenario_arg, "--clock", "lockstep", "--wait-for", "acc", "--json"]);
    sim_cmd.args(["--duration", &scenario.duration_s.to_string()]);
    let mut connect = vec![p_rec, p_acc];
    if camera {
        connect.push(p_det);
    }
    common(&mut sim_cmd, p_sim, &connect);
    sim_cmd.stdout(Stdio::piped());
    let started = Instant::now();
    let sim = sim_cmd.spawn().context("start slipstream-sim")?;
    let sim_pid = sim.id();
    let waited = tokio::time::timeout(
        Duration::from_secs_f64(args.timeout),
        tokio::task::spawn_blocking(move || sim.wait_with_output()),
    )
    .await;
    let output = match waited {
        Ok(joined) => joined.context("wait for slipstream-sim")?.context("slipstream-sim")?,
        Err(_) => {
            let _ = Command::new("kill").args(["-9", &sim_pid.to_string()]).status();
            bail!("slipstream-sim did not finish within {} s (--timeout)", args.timeout);
        }
    };
    let wall = started.elapsed().as_secs_f64();
    // Let the last messages land, then stop the nodes.
    tokio::time::sleep(Duration::from_millis(200)).await;
    for n in &mut nodes {
        n.stop(Duration::from_secs(5));
    }
    anyhow::ensure!(output.status.success(), "slipstream-sim failed ({}); run it alone to see why", output.status);
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).context("slipstream-sim --json report")?;
    let lockstep_timeouts = report["lockstep_timeouts"].as_u64().unwrap_or(0);
    let ego_collisions = report["ego_collisions"].as_u64().unwrap_or(0);
    let end = report["end"]["reason"].as_str().unwrap_or("stopped").to_string();
    let rec = recorder.take();
    drop(recorder);
    bus.close().await?;

    let mut trace = build_trace(&rec, ego_front, crate::acc::AccSettings::default().standstill_m);
    trace.collisions = ego_collisions.max(rec.collisions);
    trace.end = end.clone();
    anyhow::ensure!(trace.samples.len() > 10, "recorded only {} states (did the nodes connect?)", trace.samples.len());
    let metrics = Metrics::of(&trace);
    let plot = match &args.plots {
        Some(dir) => {
            let path = dir.join(format!("{name}.png"));
            let title =
                format!("{name} ({:?} perception): {}", args.perception, if metrics.pass { "pass" } else { "FAIL" });
            super::eval::plot(&trace, &title, &path)?;
            Some(path)
        }
        None => None,
    };
    Ok(ScenarioResult {
        scenario: name,
        perception: args.perception,
        set_speed_mps: set_speed,
        metrics,
        lockstep_timeouts,
        end,
        wall_time_s: wall,
        plot,
    })
}

/// One sample per recorded state, with the newest status and ground truth at its time.
pub(crate) fn build_trace(rec: &Recorded, ego_front: f64, standstill_m: f64) -> Trace {
    let mut states: Vec<&Received<VehicleState>> = rec.states.iter().collect();
    states.sort_by_key(|r| r.header.stamp_sim_ns);
    states.dedup_by_key(|r| r.header.stamp_sim_ns);
    let mut statuses: Vec<&Received<AccStatus>> = rec.statuses.iter().collect();
    statuses.sort_by_key(|r| r.header.stamp_sim_ns);
    let mut objects: Vec<&Received<GroundTruthObjects>> = rec.objects.iter().collect();
    objects.sort_by_key(|r| r.header.stamp_sim_ns);
    let (mut si, mut oi) = (0usize, 0usize);
    let mut samples = Vec::with_capacity(states.len());
    for st in states {
        let t = st.header.stamp_sim_ns;
        while si + 1 < statuses.len() && statuses[si + 1].header.stamp_sim_ns <= t {
            si += 1;
        }
        while oi + 1 < objects.len() && objects[oi + 1].header.stamp_sim_ns <= t {
            oi += 1;
        }
        let Some(status) = statuses.get(si).filter(|s| s.header.stamp_sim_ns <= t) else { continue };
        let truth = objects.get(oi).filter(|o| o.header.stamp_sim_ns <= t).and_then(|o| {
            let lead = truth_lead(&o.msg, st.msg.lane, ego_front)?;
            // Moved on from the frame's time at the relative speed.
            let ahead = (t - o.header.stamp_sim_ns) as f64 / 1e9;
            Some(super::eval::TruthLead { gap_m: lead.gap_m + lead.relative_speed_mps * ahead, ..lead })
        });
        samples.push(Sample::new(t as f64 / 1e9, &st.msg, &status.msg, truth));
    }
    Trace { standstill_m, samples, collisions: 0, end: String::new() }
}

/// The report as a markdown table.
pub fn markdown(report: &AccReport) -> String {
    let f = crate::bench::fmt_opt;
    let mut out = String::new();
    out.push_str("| scenario | perception | collisions | min gap m | min TTC s | time-gap RMS s | speed RMSE m/s | max accel | max decel | max jerk | emergency s | result |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
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
        out.push_str(&format!(
            "| {} | {:?} | {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.1} | {} |\n",
            r.scenario,
            r.perception,
            m.collisions,
            f(m.min_gap_m, 1),
            f(m.min_ttc_s, 2),
            f(m.time_gap_rms_error_s, 3),
            f(m.speed_rmse_mps, 3),
            m.max_accel_mps2,
            m.max_decel_mps2,
            m.max_jerk_mps3,
            m.emergency_s,
            verdict
        ));
    }
    out.push_str(&format!(
        "\nAims: no collision; time-gap RMS error <= {} s in steady following; accel <= {}, decel <= {} m/s2 and jerk <= {} m/s3 outside emergencies, at speed (+{:.0}% tolerance).\n",
        super::eval::aims::TIME_GAP_RMS_S,
        super::eval::aims::MAX_ACCEL_MPS2,
        super::eval::aims::MAX_DECEL_MPS2,
        super::eval::aims::MAX_JERK_MPS3,
        super::eval::aims::COMFORT_TOLERANCE * 100.0
    ));
    out
}
