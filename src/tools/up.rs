//! `slipstream up`: the whole loop on one machine. Starts slipstream-acc, slipstream-detect
//! and slipstream-sim as child processes through the launch layer ([`crate::launch`]), watches
//! the bus from a session of its own (live view: scenario time, ego speed, gap, ACC mode,
//! real-time factor, loop latency per hop), and at the end writes report.json, trace.csv,
//! plots and the nodes' logs into the report directory, judged by the eval layer
//! ([`crate::eval`]) exactly as `eval acc` judges its runs.
//!
//! Connection: the user's flags ([`Network::User`]): in peer mode the nodes dial this process
//! on a loopback port, and this process also listens where the config says (by default
//! tcp/127.0.0.1:7447), so `slipstream top` or `echo` in another terminal find the loop with no
//! address typed; in client mode (through a router) the nodes get the flags as given.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use parking_lot::Mutex;
use serde::Serialize;

use super::top::{KeyRow, Watcher};
use crate::acc::PerceptionSource;
use crate::bus::{CallbackSubscriber, Received};
use crate::config::{ConnectArgs, FaultArgs};
use crate::eval::judge::judge;
use crate::eval::trace::Recorder;
use crate::eval::{fmt_opt, plot, Metrics};
use crate::launch::{ClockMode, LoopRun, LoopSpec, Network, NodeEnd, NODE_POLL};
use crate::msg::{AccStatus, SimClock, SimEvent, SimEventKind};
use crate::observe::latency::{self, HopStats, LatencyWatch, LoopLatency, HOPS_SHORT, WHOLE_LOOP};
use crate::observe::NodeInput;
use crate::record::{Recording, RecordingSummary};
use crate::sim::Scenario;
use crate::vehicle::VehicleParams;
use crate::view::{LiveView, ViewOptions, ViewStats};
use crate::{topics, Bus};

pub mod egos;

/// Live view refresh on a terminal, and in plain mode (one line each).
const REFRESH_TTY: Duration = Duration::from_millis(250);
const REFRESH_PLAIN: Duration = Duration::from_millis(2000);
/// Width of the live view's progress bar, characters.
const BAR_WIDTH: usize = 24;
/// The recording's file in the report directory (`--record`).
const RECORDING: &str = "run.mcap";
/// With --record --ros2: the ROS 2 messages' recording in the report directory.
const ROS2_RECORDING: &str = "run.ros2.mcap";

#[derive(Debug, Clone, clap::Args)]
pub struct UpArgs {
    /// Scenario: a built-in name (slipstream-sim --list-scenarios) or a .json5 file
    #[arg(long, default_value = "cut-in")]
    pub scenario: String,
    /// How the simulator's clock runs (slipstream-sim --mode): realtime (paced to the wall
    /// clock), fast (as fast as it goes), lockstep (deterministic: each step waits for the ACC)
    #[arg(long, alias = "clock", value_enum, default_value = "realtime")]
    pub mode: ClockMode,
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
    /// Actuator lag for the string-stability bound, seconds [default: the scenario's ego's,
    /// 0.3 s for a car (0.2-0.5 s by class): its throttle and brake follow a command through
    /// a first-order lag]
    #[arg(long)]
    pub actuator_lag: Option<f64>,
    /// Print plain progress lines instead of the live view (the default when stderr is not a
    /// terminal)
    #[arg(long)]
    pub plain: bool,
    /// Record every key of the run into run.mcap in the report directory (docs/recording.md);
    /// with --ros2 also the ROS 2 messages into run.ros2.mcap (profile ros2, docs/ros2.md)
    #[arg(long)]
    pub record: bool,
    /// With --record: also write copies Foxglove's own panels show (camera, boxes, 3D scene,
    /// the ACC's series)
    #[arg(long, requires = "record")]
    pub viewable: bool,
    /// Serve a live view while the loop runs: a page for any browser at http://localhost:8765
    /// (camera with boxes, bird's-eye scene, plots, topics, latency per hop, nodes) and the
    /// Foxglove WebSocket on the same port (docs/viewing.md)
    #[arg(long)]
    pub view: bool,
    /// The live view's port (0: any free port, printed)
    #[arg(long, default_value_t = crate::view::DEFAULT_PORT, requires = "view")]
    pub view_port: u16,
    /// The live view's address: this machine only by default; 0.0.0.0 serves the LAN (anyone
    /// who reaches the port sees the camera: docs/viewing.md)
    #[arg(long, default_value = crate::view::DEFAULT_HOST, requires = "view")]
    pub view_host: String,
    /// Show the loop to ROS 2 while it runs (`slipstream ros2` inside `up`): camera, camera
    /// info, odometry, /tf, boxes, /clock and the ACC's status on rmw_zenoh's keys, with the
    /// mapping of config/slipstream.json5's `ros2` block (docs/ros2.md)
    #[arg(long)]
    pub ros2: bool,
    /// Which simulator the loop runs around: builtin (slipstream-sim, started here) or
    /// external (one started elsewhere: clients/python/examples/reference_sim.py, a CARLA or
    /// CoppeliaSim adapter, another PC through the router; `up` waits for its vehicle/speed
    /// and ends with its scenario, after --duration simulated seconds, or when it goes
    /// silent for 5 s; docs/simulator-contract.md)
    #[arg(long, value_enum, default_value = "builtin")]
    pub sim: SimSource,
    /// With --sim external: how long to wait for the simulator's first message, seconds
    #[arg(long, default_value_t = 60.0, value_parser = super::top::positive)]
    pub sim_wait: f64,
    /// The ACC's set speed, m/s [default: the scenario's; 25 with --sim external]
    #[arg(long, value_parser = super::top::positive)]
    pub set_speed: Option<f64>,
    #[command(flatten)]
    pub faults: FaultArgs,
    #[command(flatten)]
    pub own: slipstream_launch::OwnNodeArgs,
    /// Re-simulate: a recording (`up --record`, `slipstream record`) drives today's detector
    /// and ACC in place of the simulator, step by step, and the report compares their outputs
    /// with the recorded ones (docs/recording.md). Scenario, clock, perception and set speed
    /// come from the recording.
    #[arg(long, value_name = "FILE.mcap", conflicts_with_all = ["record", "viewable", "view", "mode", "duration", "perception", "faults"])]
    pub from: Option<PathBuf>,
}

/// Where the loop's simulator comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum SimSource {
    /// slipstream-sim, started by `up`.
    Builtin,
    /// A simulator started elsewhere, keeping docs/simulator-contract.md.
    External,
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
    pub mode: ClockMode,
    pub perception: PerceptionSource,
    /// The namespace the loop's keys live under ("" for none): the one given, or `loop-N`
    /// when the default one held another loop.
    pub namespace: String,
    pub ended: String,
    pub interrupted: bool,
    pub collisions: u64,
    /// Collisions among traffic vehicles.
    pub traffic_collisions: u64,
    pub sim_time_s: f64,
    /// `up`'s whole run, starting and stopping the nodes included.
    pub wall_time_s: f64,
    /// The simulator's own run: its report's wall time (or, with an external simulator, from
    /// its first message to the end).
    pub sim_wall_time_s: f64,
    /// Simulated seconds per second of the simulator's own run (`sim_wall_time_s`).
    pub real_time_factor: f64,
    /// In lockstep: the steps the simulator waited out without every awaited answer (none
    /// when the simulator wrote no report, or is someone else's).
    pub lockstep_timeouts: Option<u64>,
    pub nodes: Vec<NodeEnd>,
    /// The nodes of the user's own in the loop (their command and files by content), and what
    /// a loop file said of ours; empty: ours, as always.
    pub own: slipstream_launch::OwnNodes,
    pub latency: LatencyReport,
    pub metrics: Option<Metrics>,
    /// The simulator: builtin or external.
    pub sim: SimSource,
    /// The simulator published ground truth (objects): gaps, TTC and the lead's figures are
    /// judged against it; without it they are not.
    pub ground_truth: bool,
    /// Every key seen during the run (as `slipstream top` shows it), at the end.
    pub topics: Vec<KeyRow>,
    /// The fault profile the nodes injected (`--faults`), if any.
    pub faults: Option<String>,
    /// The ACC's and the simulator's inputs: lost on the way vs dropped by injected faults.
    pub inputs: Vec<NodeInput>,
    pub plots: Vec<PathBuf>,
    /// With --record: the recording and what it lost.
    pub recording: Option<RecordingSummary>,
    /// With --view: what the live view sent.
    pub view: Option<ViewStats>,
    /// With --ros2: what the ROS 2 bridge sent, per route.
    pub ros2: Option<crate::ros2::FaceStats>,
    /// With --record --ros2: what went into run.ros2.mcap, per route.
    pub ros2_recording: Option<Vec<crate::ros2::RouteStats>>,
    /// With several controlled vehicles: each one's run, judged apart (then `metrics` is
    /// none and `latency` the first ego's).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub egos: Vec<egos::EgoReport>,
    /// Collisions between two controlled vehicles (each also counted in both egos').
    pub collisions_between_egos: u64,
    pub report_dir: PathBuf,
}

/// What `up` ended with.
pub struct Outcome {
    pub report: UpReport,
}

impl Outcome {
    /// 0 clean run; 1 collision, a node died or the recording lost messages; 130 stopped
    /// with Ctrl-C.
    pub fn exit_code(&self) -> u8 {
        let r = &self.report;
        let lost = r.recording.as_ref().is_some_and(|s| s.lost_anything());
        if r.collisions > 0 || r.nodes.iter().any(|n| n.died) || lost {
            1
        } else if r.interrupted {
            130
        } else {
            0
        }
    }
}

/// `up --from FILE`: re-simulation ([`crate::eval::resim`]); prints the summary, writes the
/// report. Exit code 0 when every recorded output was answered (the same or not: differences
/// are in the report), 1 when a node died or stopped answering, 130 when a signal (Ctrl-C,
/// SIGTERM, SIGHUP) stopped it: the nodes are stopped and the report covers what was replayed.
pub fn run_from(path: &Path, args: &UpArgs, connect: &ConnectArgs) -> Result<u8> {
    anyhow::ensure!(
        path.is_file(),
        "{} is no file (a recording made with `up --record` or `slipstream record`)",
        path.display()
    );
    let stem = path.file_stem().map_or("recording".into(), |s| s.to_string_lossy().into_owned());
    let dir = match &args.report {
        Some(d) => d.clone(),
        None => super::fresh_report_dir(&format!("resim-{stem}"))?,
    };
    // The directory comes with the nodes' logs, once the recording has been read, and holds
    // report.json however the replay ends.
    eprintln!(
        "slipstream up --from {}: today's detector and ACC answer the recording; report in {}",
        path.display(),
        dir.display()
    );
    let own = args.own.nodes()?;
    let shown = super::status::Status::lines(args.plain);
    let mut progress = |t_s: f64| shown.show(&format!("replayed {t_s:.1} s"));
    let rt = tokio::runtime::Runtime::new()?;
    // A signal ends the replay early; the nodes are stopped and the report still written.
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let signal = Arc::new(Mutex::new(None::<&'static str>));
    let result = rt.block_on(async {
        let (stop2, signal2) = (stop.clone(), signal.clone());
        let watcher = tokio::spawn(async move {
            *signal2.lock() = Some(crate::cli::stop_requested().await);
            stop2.store(true, std::sync::atomic::Ordering::Relaxed);
        });
        let report = crate::eval::resim::run(path, connect, &dir, own, &mut progress, &stop).await;
        watcher.abort();
        report
    });
    shown.finish();
    // The report was announced: a replay that could not run still leaves one, saying why.
    let mut report = match result {
        Ok(r) => r,
        Err(e) => {
            let file = dir.join("report.json");
            let failed = serde_json::json!({ "recording": path, "error": e.to_string(), "complete": false });
            std::fs::create_dir_all(&dir)
                .and_then(|()| std::fs::write(&file, serde_json::to_string_pretty(&failed).unwrap_or_default()))
                .with_context(|| format!("write {}", file.display()))?;
            return Err(anyhow::Error::new(e).context(format!(
                "re-simulation of {} (report in {})",
                path.display(),
                file.display()
            )));
        }
    };
    report.stopped_by = signal.lock().map(str::to_string);
    let file = dir.join("report.json");
    std::fs::write(&file, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("write {}", file.display()))?;
    println!("{}", crate::eval::resim::summary(&report));
    Ok(match (&report.stopped_by, report.complete()) {
        (Some(_), _) => 130,
        (None, true) => 0,
        (None, false) => 1,
    })
}

/// Runs the loop to the end of the scenario (or Ctrl-C), prints the summary, writes the report.
pub fn run(args: &UpArgs, connect: &ConnectArgs) -> Result<Outcome> {
    let args = &UpArgs { sim: sim_source(args)?, ..args.clone() };
    let mut scenario = match args.sim {
        SimSource::Builtin => Scenario::find(&args.scenario)?,
        SimSource::External => external_scenario(args)?,
    };
    if let Some(d) = args.duration {
        scenario.duration_s = d;
    }
    anyhow::ensure!(
        args.actuator_lag.is_none_or(|l| l.is_finite() && l >= 0.0),
        "--actuator-lag must be a number of seconds >= 0"
    );
    let (dir, fresh) = match &args.report {
        Some(d) => (d.clone(), !d.exists()),
        None => (super::fresh_report_dir(&scenario.name)?, true),
    };
    let several = scenario.egos().len() > 1;
    if several {
        egos::check_args(args, &scenario, &connect.topic_map()?)?;
    }
    let rt = tokio::runtime::Runtime::new()?;
    let report = rt
        .block_on(async {
            match several {
                true => egos::run_loop(args, connect, scenario, &dir).await,
                false => run_loop(args, connect, scenario, &dir).await,
            }
        })
        .inspect_err(|_| {
            // A run that failed before anything was written (a taken view port, a namespace in
            // use) leaves no empty report directory behind; one with logs keeps them.
            if fresh {
                remove_if_empty(&dir);
            }
        })?;
    println!("{}", summary(&report));
    Ok(Outcome { report })
}

/// Removes `dir` if it holds nothing but empty directories; best effort.
fn remove_if_empty(dir: &Path) {
    fn empty(d: &Path) -> bool {
        std::fs::read_dir(d)
            .is_ok_and(|entries| entries.flatten().all(|e| e.file_type().is_ok_and(|t| t.is_dir()) && empty(&e.path())))
    }
    if empty(dir) {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// A loop file's simulator of the user's own (`simulator.command`, or `elsewhere`) makes the
/// run's simulator external: the loop knows it by its messages and its end, as with `--sim
/// external`, and starts it when it has a command.
fn sim_source(args: &UpArgs) -> Result<SimSource> {
    let own_sim = args.own.loop_file.is_some() && args.own.nodes()?.simulator.is_some();
    match (own_sim, args.sim) {
        (false, source) => Ok(source),
        (true, SimSource::Builtin) => Ok(SimSource::External),
        (true, SimSource::External) => anyhow::bail!(
            "--sim external: the loop file names the simulator already (fix: drop --sim external, or `simulator` from the file)"
        ),
    }
}

/// With --sim external the scenario is the simulator's: this one only names the run, sets
/// the ACC's speed and the ego's class (a car) for the judge, and runs until the simulator
/// ends it (a day at most).
fn external_scenario(args: &UpArgs) -> Result<Scenario> {
    let speed = args.set_speed.unwrap_or(25.0);
    let text =
        format!("{{ name: 'external', duration_s: 86400, ego: {{ lane: 1, speed_mps: {speed} }}, traffic: [] }}");
    Ok(Scenario::parse(&text, "up --sim external")?)
}

/// What `up` follows on the bus while the loop runs: the run's record (the same recorder as
/// `eval acc`), every key (as `top`), the loop latency, the clock and the scenario's end.
pub(super) struct Watch {
    pub recorder: Recorder,
    pub keys: Watcher,
    pub latency: Arc<Mutex<LoopLatency>>,
    _latency: LatencyWatch,
    clock: Arc<Mutex<Option<SimClock>>>,
    end_event: Arc<Mutex<Option<String>>>,
    _subs: [CallbackSubscriber; 2],
}

impl Watch {
    pub(super) async fn start(bus: &Bus, camera: bool) -> Result<Watch> {
        let watch = LatencyWatch::start(bus, camera).await?;
        let clock: Arc<Mutex<Option<SimClock>>> = Arc::default();
        let end_event: Arc<Mutex<Option<String>>> = Arc::default();
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
        Ok(Watch {
            recorder: Recorder::start(bus).await?,
            keys: Watcher::start(bus, &bus.topics().every_key()).await?,
            latency: watch.latency.clone(),
            _latency: watch,
            clock,
            end_event,
            _subs: [s5, s6],
        })
    }

    /// The live view's lines; `duration_s` None: no known end (an external simulator's).
    pub(super) fn lines(&self, name: &str, mode: ClockMode, duration_s: Option<f64>, alive: &[String]) -> Vec<String> {
        let hops = self.latency.lock().stats(true);
        let hop = |(h, short): (&HopStats, &&str)| format!("{short} {}/{}", fmt_opt(h.p50_ms, 1), fmt_opt(h.p99_ms, 1));
        vec![
            self.progress_line(name, mode, duration_s),
            format!("ego {}", self.ego_line()),
            format!("latency p50/p99 ms: {}", hops.iter().zip(&HOPS_SHORT).map(hop).collect::<Vec<_>>().join("  ")),
            format!("nodes alive: {}", if alive.is_empty() { "(none yet)".to_string() } else { alive.join(", ") }),
        ]
    }

    /// The run's name, clock, simulated time (a bar towards `duration_s`) and real-time factor.
    pub(super) fn progress_line(&self, name: &str, mode: ClockMode, duration_s: Option<f64>) -> String {
        let sim_s = self.recorder.rec.lock().states.last().map_or(0.0, |s| s.header.stamp_sim_ns as f64 / 1e9);
        let progress = match duration_s {
            Some(d) => {
                let frac = (sim_s / d.max(1e-9)).clamp(0.0, 1.0);
                let filled = (frac * BAR_WIDTH as f64).round() as usize;
                let bar = format!("{}{}", "#".repeat(filled), ".".repeat(BAR_WIDTH - filled));
                format!("{sim_s:6.1}/{d:.0} s [{bar}] {:3.0}%", frac * 100.0)
            }
            None => format!("{sim_s:6.1} s"),
        };
        let rtf = self.clock.lock().map(|c| c.real_time_factor as f64);
        format!("{name} [{}] {progress}  RTF {}", mode.name(), fmt_opt(rtf, 2))
    }

    /// The ego's speed, the ACC's mode with its lead, the collisions.
    pub(super) fn ego_line(&self) -> String {
        let (speed, status, collisions) = {
            let rec = self.recorder.rec.lock();
            (rec.states.last().map(|s| s.msg.speed_mps), rec.statuses.last().map(|s| s.msg.clone()), rec.collisions)
        };
        let acc = match &status {
            Some(AccStatus { mode, lead: Some(l), .. }) => {
                format!("ACC {mode:?}, lead #{} gap {:.1} m (wants {:.1})", l.id, l.gap_m, l.desired_gap_m)
            }
            Some(AccStatus { mode, .. }) => format!("ACC {mode:?}, no lead"),
            None => "ACC: no status yet".into(),
        };
        format!("{} m/s  {acc}  collisions {collisions}", fmt_opt(speed, 1))
    }
}

/// Draws the live view (or prints a plain line) until the simulator ends, a node dies or
/// a stop request (Ctrl-C, SIGTERM, SIGHUP). Returns the stop request's signal, if one came.
/// `lines` draws the view from the names of the nodes alive.
pub(super) async fn watch_until_over(
    lp: &mut LoopRun,
    lines: &dyn Fn(&[String]) -> Vec<String>,
    args: &UpArgs,
    external: Option<&crate::launch::ExternalSim>,
) -> Result<Option<&'static str>> {
    let shown = super::status::Status::lines(args.plain);
    let refresh = if shown.is_live() { REFRESH_TTY } else { REFRESH_PLAIN };
    let nodes_seen = lp.watch_all_nodes().await?;
    let ctrl_c = crate::cli::stop_requested();
    tokio::pin!(ctrl_c);
    // The end is noticed within NODE_POLL; the view is drawn at its own refresh rate.
    let mut poll = tokio::time::interval(NODE_POLL);
    let mut drawn_at: Option<Instant> = None;
    loop {
        tokio::select! {
            signal = &mut ctrl_c => return Ok(Some(signal)),
            _ = poll.tick() => {}
        }
        let over = lp.check().over() || external.is_some_and(|e| e.over(args.duration).is_some());
        if !over && drawn_at.is_some_and(|t| t.elapsed() < refresh) {
            continue;
        }
        drawn_at = Some(Instant::now());
        let lines = lines(&nodes_seen.names());
        // A block of lines in place on a terminal; one line per refresh in a log.
        shown.show(&lines.join(if shown.is_live() { "\n" } else { "  |  " }));
        if over {
            shown.finish();
            return Ok(None);
        }
    }
}

pub(super) fn loop_spec(args: &UpArgs, scenario: &Scenario) -> Result<LoopSpec> {
    Ok(LoopSpec {
        scenario: match args.sim {
            SimSource::Builtin => args.scenario.clone(),
            SimSource::External => scenario.name.clone(),
        },
        duration_s: scenario.duration_s,
        clock: args.mode,
        perception: args.perception,
        set_speed_mps: args.set_speed.unwrap_or(scenario.ego().controller_set_speed_mps()),
        time_gap_s: scenario.ego().time_gap_s,
        vehicle: Some(LoopSpec::vehicle_of(scenario)),
        faults: args.faults.profile()?,
        link: Default::default(),
        own: args.own.nodes()?,
        egos: crate::launch::EgoNodes::of(scenario),
    })
}

/// What `up` runs beside the loop when asked: the recording, the live view, the ROS 2 face
/// and its recording.
struct Extras {
    recording: Option<Recording>,
    view: Option<LiveView>,
    ros2: Option<crate::ros2::RosFace>,
    ros2_bag: Option<(crate::ros2::Bridge, Arc<crate::ros2::Bag>)>,
}

/// What the extras did, once stopped.
struct ExtrasDone {
    recording: Option<RecordingSummary>,
    view: Option<ViewStats>,
    ros2: Option<crate::ros2::FaceStats>,
    ros2_recording: Option<Vec<crate::ros2::RouteStats>>,
}

impl Extras {
    async fn start(bus: &Bus, args: &UpArgs, scenario: &Scenario, dir: &Path) -> Result<Extras> {
        let recording = match args.record {
            true => {
                let viewable = args.viewable.then(|| crate::view::Copies::new(Some(scenario)));
                Some(Recording::start_with(bus, &bus.topics().every_key(), &dir.join(RECORDING), viewable).await?)
            }
            false => None,
        };
        let view = match args.view {
            true => {
                let opts = ViewOptions::new(&args.view_host, args.view_port).with_scenario(scenario);
                let view = LiveView::start(bus, opts).await?;
                eprintln!("{}", super::view::how_to_open(&args.view_host, view.port()));
                Some(view)
            }
            false => None,
        };
        let ros2 = match args.ros2 {
            true => {
                let config = crate::ros2::Ros2Config::from_topic_map(bus.topics())?;
                let vehicle = VehicleParams::of_class(scenario.ego().class.into());
                let face = crate::ros2::RosFace::start(bus, &config, vehicle, false).await?;
                let n = face.node();
                eprintln!(
                    "ROS 2: node {} in namespace {} on domain {} ({:?} keys)",
                    n.name, n.namespace, n.domain, n.distro
                );
                Some(face)
            }
            false => None,
        };
        let ros2_bag = match args.ros2 && args.record {
            true => {
                let config = crate::ros2::Ros2Config::from_topic_map(bus.topics())?;
                let bag = Arc::new(crate::ros2::Bag::create(&dir.join(ROS2_RECORDING), &config)?);
                Some((crate::ros2::Bridge::start(bus, bag.clone()).await?, bag))
            }
            false => None,
        };
        Ok(Extras { recording, view, ros2, ros2_bag })
    }

    async fn stop(self) -> Result<ExtrasDone> {
        let view = match self.view {
            Some(v) => Some(v.stop().await),
            None => None,
        };
        let recording = match self.recording {
            Some(r) => Some(tokio::task::spawn_blocking(move || r.finish()).await??),
            None => None,
        };
        let ros2 = match self.ros2 {
            Some(b) => Some(b.stop().await),
            None => None,
        };
        let ros2_recording = match self.ros2_bag {
            Some((bridge, bag)) => {
                let routes = bridge.stop().await;
                tokio::task::spawn_blocking(move || bag.finish()).await??;
                Some(routes)
            }
            None => None,
        };
        Ok(ExtrasDone { recording, view, ros2, ros2_recording })
    }
}

/// Starts the loop's nodes: all of them, or, with --sim external, the controllers, then waits
/// for the simulator started elsewhere.
async fn start_nodes(lp: &mut LoopRun, args: &UpArgs) -> Result<Option<crate::launch::ExternalSim>> {
    if args.sim == SimSource::Builtin {
        lp.start().await?;
        return Ok(None);
    }
    let ext = crate::launch::ExternalSim::watch(lp.bus()).await?;
    lp.start_controllers().await?;
    lp.start_own_sim()?;
    let key = lp.bus().topics().key(topics::VEHICLE_SPEED.topic);
    eprintln!("waiting for the simulator on {key} (at most {:.0} s)", args.sim_wait);
    let deadline = Instant::now() + Duration::from_secs_f64(args.sim_wait);
    let mut signal = std::pin::pin!(crate::cli::stop_requested());
    loop {
        tokio::select! {
            started = ext.wait_started(NODE_POLL) => match started {
                Ok(()) => return Ok(Some(ext)),
                Err(e) if Instant::now() >= deadline => return Err(e.into()),
                Err(_) => {}
            },
            signal = &mut signal => anyhow::bail!("{signal} while waiting for the simulator"),
        }
        // A simulator the loop started (a loop file's command) that ended is not waited for.
        let progress = lp.check();
        if let (Some(status), true) = (progress.sim_ended, progress.died.is_empty()) {
            anyhow::bail!("the simulator ended ({status}) before its first message on {key}");
        }
        if let Some(node) = progress.died.first() {
            let why = lp.why_ended(node).map_or(String::new(), |e| format!(": {e}"));
            let whose = if node == "simulator" { "its" } else { "the simulator's" };
            anyhow::bail!("{node} ended before {whose} first message{why}\n(its log: {})", lp.log(node).display());
        }
    }
}

async fn run_loop(args: &UpArgs, connect: &ConnectArgs, scenario: Scenario, dir: &Path) -> Result<UpReport> {
    let started = Instant::now();
    let t0_ns = crate::msg::wall_clock_ns();
    let spec = loop_spec(args, &scenario)?;
    let faults = spec.faults.as_ref().map(|p| p.summary());
    // A simulator the loop starts from a loop file's command is in the run like ours.
    let started_here = spec.own.simulator.as_ref().is_some_and(|s| !s.elsewhere);
    let network = Network::User { connect, sim_elsewhere: args.sim == SimSource::External && !started_here };
    let mut lp = LoopRun::open(spec, network, &dir.join("logs"), "up").await.context("up")?;
    let watch = Watch::start(lp.bus(), args.perception == PerceptionSource::Camera).await?;
    let extras = Extras::start(lp.bus(), args, &scenario, dir).await?;
    eprintln!("{}", header(&scenario.name, args, &lp, dir));
    let external = start_nodes(&mut lp, args).await?;
    let sim_started = Instant::now();
    let shown = if external.is_some() { args.duration } else { Some(scenario.duration_s) };
    let name = lp.spec().scenario.clone();
    let lines = |alive: &[String]| watch.lines(&name, args.mode, shown, alive);
    let stopped_by = watch_until_over(&mut lp, &lines, args, external.as_ref()).await?;
    let sim_ran_s = sim_started.elapsed().as_secs_f64();
    say_who_died(&mut lp, stopped_by);
    let nodes = lp.stop().await;
    let wall = started.elapsed().as_secs_f64();
    let done = extras.stop().await?;
    let sim = lp.sim_report().ok();
    let inputs = lp.inputs();
    let topics_seen = watch.keys.view().keys;
    let rec = watch.recorder.take();
    let latency = std::mem::take(&mut *watch.latency.lock());
    let end_event = watch.end_event.lock().clone();
    drop(watch);

    let external_end = external.as_ref().and_then(|e| e.over(args.duration));
    let fallback = end_event.or(external_end).unwrap_or_else(|| match stopped_by {
        Some(signal) => format!("stopped ({signal})"),
        None => "stopped".into(),
    });
    let judged = judge(&rec, &scenario, sim.as_ref(), &fallback);
    let trace = judged.trace;
    let plots = judged_outputs(&trace, &latency, &scenario.name, args, t0_ns, dir)?;
    let sim_time_s = trace.samples.last().map_or(0.0, |s| s.t_s);
    let sim_wall_time_s = sim.as_ref().map_or(sim_ran_s, |s| s.wall_time_s);
    let lag_s = VehicleParams::of_class(scenario.ego().class.into()).actuator_lag_s;
    let report = UpReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        scenario: scenario.name.clone(),
        mode: args.mode,
        perception: args.perception,
        namespace: lp.bus().topics().namespace().to_string(),
        // A signal names the end: the simulator, stopped by up, reports only "stopped".
        ended: stopped_by.map_or_else(|| trace.end.clone(), |signal| format!("stopped ({signal})")),
        interrupted: stopped_by.is_some(),
        collisions: trace.collisions,
        traffic_collisions: trace.traffic_collisions,
        sim_time_s,
        wall_time_s: wall,
        sim_wall_time_s,
        real_time_factor: sim_time_s / sim_wall_time_s.max(1e-9),
        lockstep_timeouts: lockstep_timeouts(args, sim.as_ref()),
        nodes,
        own: lp.spec().own.clone(),
        latency: latency_report(&latency, args, rec.statuses.last().map(|s| s.msg.time_gap_s), lag_s),
        metrics: judged.metrics,
        sim: args.sim,
        ground_truth: !rec.objects.is_empty(),
        topics: topics_seen,
        faults,
        inputs,
        plots,
        recording: done.recording,
        view: done.view,
        ros2: done.ros2,
        ros2_recording: done.ros2_recording,
        egos: Vec::new(),
        collisions_between_egos: 0,
        report_dir: dir.to_path_buf(),
    };
    written(report, lp, dir).await
}

/// The simulator's lockstep timeouts, in lockstep with a report of its own.
pub(super) fn lockstep_timeouts(args: &UpArgs, sim: Option<&slipstream_sim::SimReport>) -> Option<u64> {
    (args.mode == ClockMode::Lockstep).then_some(sim).flatten().map(|s| s.lockstep_timeouts)
}

/// Writes report.json, then leaves the bus. The report is on disk before the session closes:
/// sessions still attached (top, echo, a Python client) can hold the close up, bounded as it is.
pub(super) async fn written(report: UpReport, lp: LoopRun, dir: &Path) -> Result<UpReport> {
    let path = dir.join("report.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("write {}", path.display()))?;
    lp.close().await;
    Ok(report)
}

/// Names each node that died before the run was over (with its last words and log), and the
/// signal that stops the run, if one did.
pub(super) fn say_who_died(lp: &mut LoopRun, stopped_by: Option<&str>) {
    for node in lp.check().died {
        let log = lp.log(&node);
        let why = lp.why_ended(&node).map_or(String::new(), |e| format!(": {e}"));
        eprintln!("{node} ended before the run was over{why}\n(its log: {})", log.display());
    }
    if let Some(signal) = stopped_by {
        eprintln!("{signal}: stopping the nodes");
    }
}

/// The run's first line: scenario, clock, perception, the namespace (and why, when the default
/// one held another loop), the report directory.
pub(super) fn header(scenario: &str, args: &UpArgs, lp: &LoopRun, dir: &Path) -> String {
    let (clock, perception) = (args.mode.name(), args.perception.name());
    let ns = lp.bus().topics().namespace();
    let place = match lp.moved() {
        Some((to, why)) => format!(
            " in namespace {to} (the default namespace holds another loop: {why}; `slipstream top -n {to}` watches this one)"
        ),
        None if !ns.is_empty() => format!(" in namespace {ns}"),
        None => String::new(),
    };
    format!("slipstream up: {scenario} ({clock} clock, {perception} perception){place}, report in {}", dir.display())
}

/// trace.csv, the run's plot and the latency plot; returns the plots written.
fn judged_outputs(
    trace: &crate::eval::Trace,
    latency: &LoopLatency,
    name: &str,
    args: &UpArgs,
    t0_ns: u64,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    trace.write_csv(&dir.join("trace.csv"))?;
    let mut plots = Vec::new();
    if trace.samples.len() > 1 {
        let path = dir.join(format!("{name}.png"));
        let title = format!("{name} ({} clock, {} perception)", args.mode.name(), args.perception.name());
        plot::plot(trace, &title, &path)?;
        plots.push(path);
    }
    if latency.series(WHOLE_LOOP, t0_ns).len() > 1 {
        let path = dir.join("latency.png");
        let title = format!("{name}: loop latency per hop ({} clock)", args.mode.name());
        plot::plot_latency(latency, t0_ns, &title, &path)?;
        plots.push(path);
    }
    Ok(plots)
}

/// `ego_lag_s`: the actuator lag of the scenario's ego, unless `--actuator-lag` says otherwise.
pub(super) fn latency_report(
    lat: &LoopLatency,
    args: &UpArgs,
    time_gap_s: Option<f64>,
    ego_lag_s: f64,
) -> LatencyReport {
    let hops = lat.stats(false);
    let delay = hops[WHOLE_LOOP].p99_ms.map(|ms| ms / 1e3);
    let lag = args.actuator_lag.unwrap_or(ego_lag_s);
    LatencyReport {
        loop_delay_p99_s: delay,
        actuator_lag_s: lag,
        min_stable_time_gap_s: delay.map(|d| latency::min_stable_time_gap_s(d, lag)),
        time_gap_s,
        hops,
        note: match args.mode {
            ClockMode::Realtime => "realtime: the vehicle feels this delay",
            _ => "fast/lockstep: wall-clock delay does not delay the simulated vehicle; run with --mode realtime for the bound to apply",
        },
    }
}

/// The summary printed at the end.
pub fn summary(r: &UpReport) -> String {
    let f = fmt_opt;
    let mut s =
        format!(
        "\n{} ({} clock, {} perception): {}\n  {:.1} s simulated in {:.1} s (real-time factor {:.2}; {:.1} s with the nodes' start and stop); collisions {} (traffic among itself: {})\n",
        r.scenario,
        r.mode.name(),
        r.perception.name(),
        r.ended,
        r.sim_time_s,
        r.sim_wall_time_s,
        r.real_time_factor,
        r.wall_time_s,
        r.collisions,
        r.traffic_collisions
    );
    if r.mode == ClockMode::Realtime && r.sim_time_s > 1.0 && r.real_time_factor < MIN_REALTIME_FACTOR {
        s.push_str(&format!(
            "  WARNING: this realtime run did not keep real time (real-time factor {:.2} < {MIN_REALTIME_FACTOR}): the machine could not run the loop at the wall clock's pace, so its latencies and what the ACC felt are a slowed loop's (fix: free the cores, or --mode lockstep, which does not depend on the machine's speed)\n",
            r.real_time_factor
        ));
    }
    if let Some(m) = &r.metrics {
        s.push_str(&acc_figures(m));
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
    if !r.egos.is_empty() {
        s.push_str(&egos::table(&r.egos, r.collisions_between_egos));
    }
    if !r.ground_truth {
        s.push_str(
            "  no ground truth: the simulator published no objects, so gaps, TTC and the lead's figures are not judged \
             (docs/simulator-contract.md, optional parts)\n",
        );
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
    if let Some(faults) = &r.faults {
        s.push_str(&format!("  faults injected: {faults}\n"));
    }
    for i in &r.inputs {
        let st = &i.stats;
        if r.faults.is_some() || st.lost > 0 {
            s.push_str(&format!("    {}\n", i.line()));
        }
    }
    if let Some(k) = r.lockstep_timeouts {
        s.push_str(&format!("  lockstep timeouts: {k} (steps the simulator waited out without every answer)\n"));
    }
    for n in &r.nodes {
        s.push_str(&format!(
            "  {:<18} pid {:>7}  exit {:<5} {}{}log {}\n",
            n.node,
            n.pid,
            n.exit_code.map_or("signal".into(), |c| c.to_string()),
            if n.died { "DIED  " } else { "" },
            if n.restarts > 0 { format!("restarted {}x  ", n.restarts) } else { String::new() },
            n.log.display()
        ));
    }
    s.push_str(&format!("  report: {}", r.report_dir.join("report.json").display()));
    for p in &r.plots {
        s.push_str(&format!(", {}", p.display()));
    }
    if let Some(v) = &r.view {
        s.push_str(&format!("\n  live view: {}", super::view::status_line(v)));
    }
    if let Some(rec) = &r.recording {
        s.push('\n');
        s.push_str(&rec.render(crate::cli::colour(&std::io::stdout())));
    }
    s
}

/// The ACC's figures of the summary: the aims missed by name, and why a figure is "-".
fn acc_figures(m: &Metrics) -> String {
    let [gap, ttc, time_gap, speed, accel, decel, jerk] = m.headline();
    let missed: Vec<&str> = m.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect();
    let verdict = match missed.is_empty() {
        true => "meets the ACC aims".to_string(),
        false => format!("misses the ACC aims: {}", missed.join(", ")),
    };
    let mut s = format!(
        "  min gap {gap} m, min TTC {ttc} s, time-gap RMS error {time_gap} s, speed RMSE {speed} m/s, max accel {accel} / decel {decel} m/s2, max jerk {jerk} m/s3 ({verdict})\n"
    );
    let mut why = Vec::new();
    if m.time_gap_rms_error_s.is_none() {
        why.push("time-gap RMS: the ego never followed a lead steadily (judged only then)");
    }
    if m.speed_rmse_mps.is_none() {
        why.push("speed RMSE: the ego never cruised at its set speed for a while with nothing to follow");
    }
    if !why.is_empty() {
        s.push_str(&format!("  (- : {})\n", why.join("; ")));
    }
    s
}

/// A realtime run below this real-time factor did not keep real time: the summary says so.
const MIN_REALTIME_FACTOR: f64 = 0.95;

/// `slipstream up`: the loop (or `--from` a recording); exit 1 on a collision or a dead node.
pub fn command(args: &UpArgs, connect: &ConnectArgs) -> Result<std::process::ExitCode> {
    Ok(std::process::ExitCode::from(match &args.from {
        Some(path) => run_from(path, args, connect)?,
        None => run(args, connect)?.exit_code(),
    }))
}
