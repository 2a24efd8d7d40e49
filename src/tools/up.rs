//! `slipstream up`: the whole loop on one machine. Starts slipstream-acc, slipstream-detect
//! and slipstream-sim as child processes, watches the bus from a session of its own (live
//! view: scenario time, ego speed, gap, ACC mode, real-time factor, loop latency per hop),
//! and at the end writes report.json, plots and the nodes' logs into the report directory.
//!
//! Connection: in peer mode (the default config) every child listens on a loopback port of
//! its own and connects to this process and to the children started before it, so the loop
//! does not depend on discovery; this process also listens where the config says (the
//! default: tcp/127.0.0.1:7447), so `slipstream top` or `echo` in another terminal find the
//! loop with no address typed. In client mode (through a router) the children get the
//! connection flags as given.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use parking_lot::Mutex;
use serde::Serialize;

use super::children::{free_ports, sibling_binary, Child};
use super::latency::{self, HopStats, LoopLatency};
use crate::acc::eval::Metrics;
use crate::acc::settings::PerceptionSource;
use crate::acc::suite::{build_trace, Recorder};
use crate::bus::Received;
use crate::config::ConnectArgs;
use crate::msg::{AccStatus, SimClock, SimEvent, SimEventKind};
use crate::sim::vehicle::VehicleParams;
use crate::sim::Scenario;
use crate::topics;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum UpMode {
    /// Paced to the wall clock: watch it drive; latency is felt by the vehicle
    Realtime,
    /// As fast as the simulator can; the detector and the ACC may fall behind
    Fast,
    /// Every step waits for the ACC's answer: deterministic, as fast as the loop allows
    Lockstep,
}

#[derive(Debug, Clone, clap::Args)]
pub struct UpArgs {
    /// Scenario: a built-in name (slipstream-sim --list-scenarios) or a .json5 file
    #[arg(long, default_value = "cut-in")]
    pub scenario: String,
    /// How the simulator's clock runs (slipstream-sim --clock)
    #[arg(long, alias = "clock", value_enum, default_value = "realtime")]
    pub mode: UpMode,
    /// Where report.json, the plots and the nodes' logs go
    /// [default: reports/<scenario>-<UTC date>-<time>]
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Where the ACC's vehicles ahead come from: camera (slipstream-detect on the rendered
    /// frames) or ground-truth (the simulator's objects; no detector is started)
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// End after this many simulated seconds instead of the scenario's own duration
    #[arg(long, value_parser = super::top::positive)]
    pub duration: Option<f64>,
    /// Actuator lag of the vehicle you have in mind, seconds, for the string-stability bound
    /// (the simulated car has none: a command acts at the next physics step)
    #[arg(long, default_value_t = 0.0)]
    pub actuator_lag: f64,
    /// Print plain progress lines instead of the live view (the default when stderr is not a
    /// terminal)
    #[arg(long)]
    pub plain: bool,
}

/// How a node process ended.
#[derive(Debug, Clone, Serialize)]
pub struct NodeEnd {
    pub node: String,
    pub pid: u32,
    /// Exit code; None when killed by a signal.
    pub exit_code: Option<i32>,
    /// Ended on its own before the run was over.
    pub died: bool,
    pub log: PathBuf,
}

#[derive(Debug, Clone, Serialize)]
pub struct LatencyReport {
    pub hops: Vec<HopStats>,
    /// Loop delay (frame published -> control applied), p99, seconds.
    pub loop_delay_p99_s: Option<f64>,
    pub actuator_lag_s: f64,
    /// h > 2 (delay + actuator lag): the smallest time gap a string of such vehicles stays
    /// stable at.
    pub min_stable_time_gap_s: Option<f64>,
    /// The ACC's time gap in the run.
    pub time_gap_s: Option<f64>,
    pub note: &'static str,
}

#[derive(Debug, Clone, Serialize)]
pub struct UpReport {
    pub command: String,
    pub scenario: String,
    pub mode: UpMode,
    pub perception: PerceptionSource,
    pub ended: String,
    pub interrupted: bool,
    pub collisions: u64,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    pub real_time_factor: f64,
    pub nodes: Vec<NodeEnd>,
    pub latency: LatencyReport,
    pub metrics: Option<Metrics>,
    /// Every key seen during the run (as `slipstream top` shows it), at the end.
    pub topics: Vec<super::top::KeyRow>,
    pub plots: Vec<PathBuf>,
    pub report_dir: PathBuf,
}

/// What `up` ended with.
pub struct Outcome {
    pub report: UpReport,
}

impl UpMode {
    pub fn name(self) -> &'static str {
        match self {
            UpMode::Realtime => "realtime",
            UpMode::Fast => "fast",
            UpMode::Lockstep => "lockstep",
        }
    }
}

fn perception_name(p: PerceptionSource) -> &'static str {
    match p {
        PerceptionSource::Camera => "camera",
        PerceptionSource::GroundTruth => "ground-truth",
    }
}

impl Outcome {
    /// 0 clean run; 1 collision or a node died; 130 stopped with Ctrl-C.
    pub fn exit_code(&self) -> i32 {
        let r = &self.report;
        if r.collisions > 0 || r.nodes.iter().any(|n| n.died) {
            1
        } else if r.interrupted {
            130
        } else {
            0
        }
    }
}

/// Runs the loop to the end of the scenario (or Ctrl-C), prints the summary, writes the report.
pub fn run(args: &UpArgs, connect: &ConnectArgs) -> Result<Outcome> {
    let mut scenario = Scenario::find(&args.scenario)?;
    if let Some(d) = args.duration {
        scenario.duration_s = d;
    }
    anyhow::ensure!(
        args.actuator_lag.is_finite() && args.actuator_lag >= 0.0,
        "--actuator-lag must be a number of seconds >= 0"
    );
    let dir = match &args.report {
        Some(d) => d.clone(),
        None => PathBuf::from("reports").join(format!("{}-{}", scenario.name, utc_stamp())),
    };
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("create the report directory {}", logs.display()))?;
    let rt = tokio::runtime::Runtime::new()?;
    let report = rt.block_on(run_loop(args, connect, scenario, &dir))?;
    let path = dir.join("report.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("write {}", path.display()))?;
    println!("{}", summary(&report));
    Ok(Outcome { report })
}

/// What the live view shows, refreshed from the recordings.
struct Live {
    clock: Option<SimClock>,
    sim_s: f64,
}

async fn run_loop(args: &UpArgs, connect: &ConnectArgs, scenario: Scenario, dir: &Path) -> Result<UpReport> {
    let started = Instant::now();
    let t0_ns = crate::msg::wall_clock_ns();
    let name = scenario.name.clone();
    let camera = args.perception == PerceptionSource::Camera;
    let set_speed = scenario.ego.set_speed_mps.unwrap_or(scenario.ego.speed_mps);

    // This process's session: the config as the user gave it, plus a loopback port the
    // children connect to.
    let mut config = connect.zenoh_config()?;
    let mode = config.get_json("mode").ok().and_then(|m| serde_json::from_str::<String>(&m).ok());
    let peer = mode.as_deref().unwrap_or("peer") == "peer";
    anyhow::ensure!(mode.as_deref() != Some("router"), "up runs its nodes as peers or clients, not routers (-m)");
    let [p_up, p_acc, p_det, p_sim] = free_ports::<4>()?;
    let ep = |p: u16| format!("tcp/127.0.0.1:{p}");
    if peer {
        let mut listen: Vec<serde_json::Value> =
            config.get_json("listen/endpoints").ok().and_then(|s| serde_json::from_str(&s).ok()).unwrap_or_default();
        listen.push(ep(p_up).into());
        config
            .insert_json5("listen/endpoints", &serde_json::Value::Array(listen).to_string())
            .map_err(|e| anyhow::anyhow!("add a listen endpoint for the nodes: {e}"))?;
    }
    let topic_map = connect.topic_map()?;
    let bus = crate::Bus::open(config, topic_map, "up").await.context("up: join the bus")?;
    let recorder = Recorder::start(&bus).await?;
    let watcher = super::top::Watcher::start(&bus).await?;
    let lat = Arc::new(Mutex::new(LoopLatency::default()));
    let clock: Arc<Mutex<Option<SimClock>>> = Arc::default();
    let end_event: Arc<Mutex<Option<String>>> = Arc::default();
    let subs = {
        let l = lat.clone();
        let s1 = bus
            .subscribe_with(topics::PERCEPTION_OBJECTS, move |d| {
                l.lock().on_detections(d.header.stamp_pub_ns, d.msg.frame_stamp_pub_ns)
            })
            .await?;
        let l = lat.clone();
        let s2 = bus
            .subscribe_with(topics::VEHICLE_CONTROL, move |c| {
                l.lock().on_command(c.header.stamp_pub_ns, c.msg.perception_stamp_pub_ns)
            })
            .await?;
        let l = lat.clone();
        let s3 = bus
            .subscribe_with(topics::VEHICLE_STATE, move |s| {
                if let Some(t) = s.msg.control_timing {
                    l.lock().on_applied(t.command_stamp_pub_ns, t.applied_ns);
                }
            })
            .await?;
        // Ground truth is the perception only without the camera.
        let l = lat.clone();
        let s4 = bus
            .subscribe_with(topics::OBJECTS, move |o| {
                if !camera {
                    l.lock().on_ground_truth(o.header.stamp_pub_ns)
                }
            })
            .await?;
        let c = clock.clone();
        let s5 = bus.subscribe_with(topics::SIM_CLOCK, move |m| *c.lock() = Some(m.msg)).await?;
        let e = end_event.clone();
        let s6 = bus
            .subscribe_with(topics::SIM_EVENTS, move |m: Received<SimEvent>| {
                if let SimEventKind::ScenarioEnd { reason, .. } = m.msg.kind {
                    *e.lock() = Some(reason);
                }
            })
            .await?;
        [s1, s2, s3, s4, s5, s6]
    };

    // The children's connection flags.
    let mut base: Vec<String> = Vec::new();
    if let Some(c) = &connect.zenoh_config {
        base.extend(["-c".into(), c.display().to_string()]);
    }
    if let Some(t) = &connect.topics {
        base.extend(["-t".into(), t.display().to_string()]);
    }
    if let Some(n) = &connect.namespace {
        base.extend(["-n".into(), n.clone()]);
    }
    if let Some(m) = connect.mode {
        base.extend(["-m".into(), format!("{m:?}").to_lowercase()]);
    }
    if connect.no_multicast_scouting {
        base.push("--no-multicast-scouting".into());
    }
    for kv in &connect.cfg {
        base.extend(["--cfg".into(), kv.clone()]);
    }
    let flags = |own: u16, earlier: &[u16]| -> Vec<String> {
        let mut f = base.clone();
        if peer {
            f.extend(["-l".into(), ep(own)]);
            for p in std::iter::once(&p_up).chain(earlier) {
                f.extend(["-e".into(), ep(*p)]);
            }
            for e in &connect.connect {
                f.extend(["-e".into(), e.clone()]);
            }
        } else {
            for e in &connect.connect {
                f.extend(["-e".into(), e.clone()]);
            }
        }
        f
    };
    let logs = dir.join("logs");
    let spawn = |bin: &str, args: Vec<String>, own: u16, earlier: &[u16], stdout: &str| -> Result<Child> {
        let log = std::fs::File::create(logs.join(format!("{bin}.log")))?;
        let out = std::fs::File::create(logs.join(stdout))?;
        let mut cmd = Command::new(sibling_binary(bin)?);
        cmd.args(flags(own, earlier)).args(args).stdin(Stdio::null()).stdout(out).stderr(log);
        if std::env::var_os("RUST_LOG").is_none() {
            cmd.env("RUST_LOG", "info,zenoh=warn,zenoh_ext=warn");
        }
        Child::spawn(bin, &mut cmd)
    };

    let lockstep = args.mode == UpMode::Lockstep;
    let mut nodes: Vec<Child> = Vec::new();
    let mut acc_args = vec![
        "--set-speed".to_string(),
        set_speed.to_string(),
        "--perception".into(),
        if camera { "camera" } else { "ground-truth" }.into(),
    ];
    if lockstep {
        acc_args.push("--lockstep".into());
    }
    nodes.push(spawn("slipstream-acc", acc_args, p_acc, &[], "slipstream-acc.out")?);
    let mut up_ports = vec![p_acc];
    if camera {
        nodes.push(spawn("slipstream-detect", vec![], p_det, &[p_acc], "slipstream-detect.out")?);
        up_ports.push(p_det);
    }
    let plain = args.plain || !std::io::stderr().is_terminal();
    eprintln!(
        "slipstream up: {name} ({} clock, {} perception), report in {}",
        args.mode.name(),
        perception_name(args.perception),
        dir.display()
    );
    // The simulator's first frame must find the detector and the ACC listening.
    let wanted: Vec<&str> = if camera { vec!["acc", "detect"] } else { vec!["acc"] };
    let nodes_seen = bus.watch_nodes().await?;
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let alive = nodes_seen.names();
        if wanted.iter().all(|w| alive.iter().any(|a| a == w)) {
            break;
        }
        for n in &mut nodes {
            if let Some(status) = n.exited() {
                bail!("{} exited at start ({status}); see {}", n.name, logs.join(format!("{}.log", n.name)).display());
            }
        }
        anyhow::ensure!(
            Instant::now() < deadline,
            "{wanted:?} not all up after 30 s (alive: {alive:?}); see {}",
            logs.display()
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let mut sim_args = vec![
        "--scenario".to_string(),
        // A file is passed as given; a built-in by its name.
        args.scenario.clone(),
        "--clock".into(),
        args.mode.name().into(),
        "--duration".into(),
        scenario.duration_s.to_string(),
        "--json".into(),
    ];
    if lockstep {
        sim_args.extend(["--wait-for".into(), "acc".into()]);
    }
    nodes.push(spawn("slipstream-sim", sim_args, p_sim, &up_ports, "slipstream-sim.json")?);
    let sim_ix = nodes.len() - 1;

    // Watch until the simulator ends, a node dies, or Ctrl-C.
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let refresh = Duration::from_millis(if plain { 2000 } else { 250 });
    let mut tick = tokio::time::interval(refresh);
    let mut drawn_lines = 0usize;
    let mut interrupted = false;
    let mut died: Vec<usize> = Vec::new();
    loop {
        tokio::select! {
            _ = &mut ctrl_c => { interrupted = true; break; }
            _ = tick.tick() => {}
        }
        for (i, n) in nodes.iter_mut().enumerate() {
            if i != sim_ix && n.exited().is_some() {
                died.push(i);
            }
        }
        let sim_done = nodes[sim_ix].exited();
        if let Some(status) = sim_done {
            if !status.success() {
                died.push(sim_ix);
            }
        }
        let live = Live {
            clock: *clock.lock(),
            sim_s: recorder.rec.lock().states.last().map_or(0.0, |s| s.header.stamp_sim_ns as f64 / 1e9),
        };
        let lines = live_lines(&name, args, scenario.duration_s, &live, &recorder, &lat.lock(), &nodes_seen.names());
        let mut err = std::io::stderr().lock();
        if plain {
            let _ = writeln!(err, "{}", lines.join("  |  "));
        } else {
            if drawn_lines > 0 {
                let _ = write!(err, "\x1b[{drawn_lines}A");
            }
            for l in &lines {
                let _ = writeln!(err, "\x1b[2K{l}");
            }
            drawn_lines = lines.len();
        }
        let _ = err.flush();
        if sim_done.is_some() || !died.is_empty() {
            break;
        }
    }
    died.sort_unstable();
    died.dedup();
    for &i in &died {
        let status = nodes[i].exited().map_or("?".into(), |s| s.to_string());
        let name = &nodes[i].name;
        eprintln!(
            "{name} ended before the run was over ({status}); see {}",
            logs.join(format!("{name}.log")).display()
        );
    }
    if interrupted {
        eprintln!("Ctrl-C: stopping the nodes");
    }
    // The simulator first (it publishes the scenario's end), then the others.
    nodes[sim_ix].stop(Duration::from_secs(5));
    tokio::time::sleep(Duration::from_millis(200)).await;
    for n in nodes.iter_mut() {
        n.stop(Duration::from_secs(5));
    }
    let wall = started.elapsed().as_secs_f64();
    let node_ends: Vec<NodeEnd> = nodes
        .iter_mut()
        .enumerate()
        .map(|(i, n)| NodeEnd {
            node: n.name.clone(),
            pid: n.pid(),
            exit_code: n.exited().and_then(|s| s.code()),
            died: died.contains(&i),
            log: logs.join(format!("{}.log", n.name)),
        })
        .collect();

    let sim_json: Option<serde_json::Value> =
        std::fs::read(logs.join("slipstream-sim.json")).ok().and_then(|b| serde_json::from_slice(&b).ok());
    let topics_seen = watcher.view(&bus).keys;
    let rec = recorder.take();
    drop((subs, recorder, watcher, nodes_seen));
    bus.close().await?;

    let ego = VehicleParams::of_class(scenario.ego.class.into());
    let mut trace =
        build_trace(&rec, ego.size_m[0] - ego.rear_overhang_m, crate::acc::AccSettings::default().standstill_m);
    let sim_collisions = sim_json.as_ref().and_then(|j| j["ego_collisions"].as_u64()).unwrap_or(0);
    trace.collisions = sim_collisions.max(rec.collisions);
    let ended = sim_json
        .as_ref()
        .and_then(|j| j["end"]["reason"].as_str().map(String::from))
        .or_else(|| end_event.lock().clone())
        .unwrap_or_else(|| if interrupted { "stopped (Ctrl-C)".into() } else { "stopped".into() });
    trace.end = ended.clone();
    let sim_time_s = trace.samples.last().map_or(0.0, |s| s.t_s);
    let metrics = (trace.samples.len() > 10).then(|| Metrics::of(&trace));

    write_trace_csv(&trace, &dir.join("trace.csv"))?;
    let mut plots = Vec::new();
    if trace.samples.len() > 1 {
        let path = dir.join(format!("{name}.png"));
        let title = format!("{name} ({} clock, {} perception)", args.mode.name(), perception_name(args.perception));
        crate::acc::eval::plot(&trace, &title, &path)?;
        plots.push(path);
    }
    let lat = lat.lock();
    if lat.series(3, t0_ns).len() > 1 {
        let path = dir.join("latency.png");
        plot_latency(&lat, t0_ns, &format!("{name}: loop latency per hop ({} clock)", args.mode.name()), &path)?;
        plots.push(path);
    }
    let hops = lat.stats(false);
    let delay = hops[3].p99_ms.map(|ms| ms / 1e3);
    let time_gap_s = rec.statuses.last().map(|s| s.msg.time_gap_s);
    let latency = LatencyReport {
        loop_delay_p99_s: delay,
        actuator_lag_s: args.actuator_lag,
        min_stable_time_gap_s: delay.map(|d| latency::min_stable_time_gap_s(d, args.actuator_lag)),
        time_gap_s,
        hops,
        note: match args.mode {
            UpMode::Realtime => "realtime: the vehicle feels this delay",
            _ => "fast/lockstep: wall-clock delay does not delay the simulated vehicle; run with --mode realtime for the bound to apply",
        },
    };
    Ok(UpReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        scenario: name,
        mode: args.mode,
        perception: args.perception,
        ended,
        interrupted,
        collisions: trace.collisions,
        sim_time_s,
        wall_time_s: wall,
        real_time_factor: sim_time_s / wall.max(1e-9),
        nodes: node_ends,
        latency,
        metrics,
        topics: topics_seen,
        plots,
        report_dir: dir.to_path_buf(),
    })
}

/// The live view's lines.
fn live_lines(
    name: &str,
    args: &UpArgs,
    duration_s: f64,
    live: &Live,
    recorder: &Recorder,
    lat: &LoopLatency,
    alive: &[String],
) -> Vec<String> {
    let f = crate::bench::fmt_opt;
    let frac = (live.sim_s / duration_s.max(1e-9)).clamp(0.0, 1.0);
    let width = 24;
    let filled = (frac * width as f64).round() as usize;
    let bar = format!("{}{}", "#".repeat(filled), ".".repeat(width - filled));
    let (speed, status, collisions) = {
        let rec = recorder.rec.lock();
        (rec.states.last().map(|s| s.msg.speed_mps), rec.statuses.last().map(|s| s.msg.clone()), rec.collisions)
    };
    let acc = match &status {
        Some(AccStatus { mode, lead: Some(l), .. }) => {
            format!("ACC {mode:?}, lead #{} gap {:.1} m (wants {:.1})", l.id, l.gap_m, l.desired_gap_m)
        }
        Some(AccStatus { mode, .. }) => format!("ACC {mode:?}, no lead"),
        None => "ACC: no status yet".into(),
    };
    let rtf = live.clock.map(|c| c.real_time_factor as f64);
    let hops = lat.stats(true);
    let hop = |(h, short): (&HopStats, &&str)| format!("{short} {}/{}", f(h.p50_ms, 1), f(h.p99_ms, 1));
    vec![
        format!(
            "{name} [{}] {:6.1}/{:.0} s [{bar}] {:3.0}%  RTF {}",
            args.mode.name(),
            live.sim_s,
            duration_s,
            frac * 100.0,
            f(rtf, 2)
        ),
        format!("ego {} m/s  {acc}  collisions {collisions}", f(speed, 1)),
        format!(
            "latency p50/p99 ms: {}",
            hops.iter().zip(&latency::HOPS_SHORT).map(hop).collect::<Vec<_>>().join("  ")
        ),
        format!("nodes alive: {}", if alive.is_empty() { "(none yet)".to_string() } else { alive.join(", ") }),
    ]
}

/// The summary printed at the end.
pub fn summary(r: &UpReport) -> String {
    let f = crate::bench::fmt_opt;
    let mut s =
        format!(
        "\n{} ({} clock, {} perception): {}\n  {:.1} s simulated in {:.1} s (real-time factor {:.2}); collisions {}\n",
        r.scenario,
        r.mode.name(),
        perception_name(r.perception), r.ended, r.sim_time_s, r.wall_time_s, r.real_time_factor, r.collisions
    );
    if let Some(m) = &r.metrics {
        s.push_str(&format!(
            "  min gap {} m, min TTC {} s, time-gap RMS error {} s, speed RMSE {} m/s, max accel {:.2} / decel {:.2} m/s2, max jerk {:.2} m/s3 ({})\n",
            f(m.min_gap_m, 1),
            f(m.min_ttc_s, 2),
            f(m.time_gap_rms_error_s, 3),
            f(m.speed_rmse_mps, 3),
            m.max_accel_mps2,
            m.max_decel_mps2,
            m.max_jerk_mps3,
            if m.pass { "meets the ACC aims" } else { "misses an ACC aim" }
        ));
    }
    s.push_str("\n  loop latency            count    p50 ms    p99 ms    max ms\n");
    for h in &r.latency.hops {
        s.push_str(&format!(
            "  {:<22} {:>6} {:>9} {:>9} {:>9}\n",
            h.hop,
            h.count,
            f(h.p50_ms, 2),
            f(h.p99_ms, 2),
            f(h.max_ms, 2)
        ));
    }
    if let Some(h) = r.latency.min_stable_time_gap_s {
        s.push_str(&format!(
            "  string stability: h > 2 x (delay {:.3} s + actuator lag {:.3} s) = {:.3} s; the ACC runs at {} s ({})\n",
            r.latency.loop_delay_p99_s.unwrap_or(0.0),
            r.latency.actuator_lag_s,
            h,
            f(r.latency.time_gap_s, 2),
            r.latency.note
        ));
    }
    for n in &r.nodes {
        s.push_str(&format!(
            "  {:<18} pid {:>7}  exit {:<5} {}log {}\n",
            n.node,
            n.pid,
            n.exit_code.map_or("signal".into(), |c| c.to_string()),
            if n.died { "DIED  " } else { "" },
            n.log.display()
        ));
    }
    s.push_str(&format!("  report: {}", r.report_dir.join("report.json").display()));
    for p in &r.plots {
        s.push_str(&format!(", {}", p.display()));
    }
    s
}

/// One row per vehicle/state: what the plot shows, for a spreadsheet or pandas.
fn write_trace_csv(trace: &crate::acc::eval::Trace, path: &Path) -> Result<()> {
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    let mut out = String::from(
        "t_s,speed_mps,accel_mps2,acc_mode,target_accel_mps2,set_speed_mps,time_gap_s,acc_gap_m,truth_gap_m,truth_lead_speed_mps\n",
    );
    for x in &trace.samples {
        out.push_str(&format!(
            "{:.3},{:.4},{:.4},{:?},{:.4},{:.3},{:.3},{},{},{}\n",
            x.t_s,
            x.speed_mps,
            x.accel_mps2,
            x.mode,
            x.target_accel_mps2,
            x.set_speed_mps,
            x.time_gap_s,
            opt(x.acc_gap_m),
            opt(x.truth.map(|t| t.gap_m)),
            opt(x.truth.map(|t| x.speed_mps + t.relative_speed_mps)),
        ));
    }
    std::fs::write(path, out).with_context(|| format!("write {}", path.display()))
}

/// Loop latency per hop over the run.
fn plot_latency(lat: &LoopLatency, t0_ns: u64, title: &str, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    crate::acc::eval::register_font()?;
    let (w, h) = (1100u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    let series: Vec<Vec<(f64, f64)>> = (0..latency::HOPS.len()).map(|i| lat.series(i, t0_ns)).collect();
    let t_end = series.iter().flatten().map(|p| p.0).fold(1.0f64, f64::max);
    let hi = series.iter().flatten().map(|p| p.1).fold(1.0f64, f64::max) * 1.1;
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, 0.0..hi)?;
        chart.configure_mesh().x_desc("wall time (s)").y_desc("latency (ms)").label_style(("sans-serif", 14)).draw()?;
        let colors = [RGBColor(31, 119, 180), RGBColor(255, 127, 14), RGBColor(44, 160, 44), RGBColor(214, 39, 40)];
        for ((name, pts), color) in latency::HOPS.iter().zip(series).zip(colors) {
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))?
                .label(*name)
                .legend(move |(x, y)| Circle::new((x + 9, y), 4, color.filled()));
        }
        crate::acc::eval::draw_legend(&mut chart)?;
        root.present()?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).context("plot buffer size")?;
    img.save(path).with_context(|| format!("write {}", path.display()))?;
    Ok(())
}

/// UTC date and time for directory names: 20261122-041530.
fn utc_stamp() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_stamp_has_the_shape_of_a_date() {
        let s = super::utc_stamp();
        assert_eq!(s.len(), 15, "{s}");
        assert!(s.starts_with("20"), "{s}");
        let month: u32 = s[4..6].parse().unwrap();
        let day: u32 = s[6..8].parse().unwrap();
        assert!((1..=12).contains(&month) && (1..=31).contains(&day), "{s}");
    }
}
