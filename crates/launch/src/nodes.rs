//! The loop as child processes: slipstream-acc, slipstream-detect (camera perception only) and
//! slipstream-sim, watched from an observer session of the launcher's own.
//!
//! The order is fixed: [`LoopRun::open`] joins the bus (the caller subscribes to what it records
//! before anything is published), [`LoopRun::start`] starts the controllers, waits until their
//! liveliness tokens are seen, then starts the simulator; [`LoopRun::check`] reports its end or
//! a node's death; [`LoopRun::stop`] stops the simulator first (it publishes the scenario's
//! end), lets the last messages land, then the others; [`LoopRun::close`] leaves the bus.
//!
//! Connection, by [`Network`]: with the user's flags in peer mode every node listens on a
//! loopback port of its own and dials the observer and the nodes started before it, so the
//! loop does not depend on discovery, and the observer also listens where the config says
//! (by default tcp/127.0.0.1:7447, so `slipstream top` in another terminal finds the loop); in
//! client mode (through a router) the nodes get the flags as given. [`Network::Isolated`] uses
//! only loopback ports and a namespace of the run's own: nothing else on the machine is seen
//! or disturbed (the suites).

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};

use crate::error::{Error, Result};
use serde::Serialize;
use slipstream_observe::NodeInput;

use super::child::{free_ports, sibling_binary};
use super::foreign::{ForeignNode, NodeRun, OwnNodes, RestartPolicy, Role};
use super::supervise::{State, Supervised};
use super::{SETTLE, STOP_GRACE};
use slipstream_acc::node::AccStats;
use slipstream_acc::{PerceptionSource, VehicleClass};
use slipstream_contract::config::{ConnectArgs, FaultProfile, DEFAULT_ZENOH_CONFIG};
use slipstream_contract::Bus;
use slipstream_perception::node::DetectStats;
use slipstream_sim::SimReport;

mod egos;
pub use egos::{AllNodes, EgoNodes};

/// How the simulator's clock runs (slipstream-sim --mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ClockMode {
    /// Paced to the wall clock: watch it drive; latency is felt by the vehicle
    Realtime,
    /// As fast as the simulator can; the detector and the ACC may fall behind
    Fast,
    /// Every step waits for the ACC's answer: deterministic, as fast as the loop allows
    Lockstep,
}

impl ClockMode {
    pub fn name(self) -> &'static str {
        match self {
            ClockMode::Realtime => "realtime",
            ClockMode::Fast => "fast",
            ClockMode::Lockstep => "lockstep",
        }
    }
}

/// How the loop's processes on this host reach each other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LinkKind {
    /// Unix sockets in a directory of the run's own: no TCP/IP stack between processes
    /// (about half the latency of TCP on loopback, docs/performance.md)
    #[default]
    Unix,
    /// TCP on loopback ports
    Tcp,
}

/// Which loop to run.
#[derive(Debug, Clone)]
pub struct LoopSpec {
    /// As given to slipstream-sim --scenario: a built-in name or a .json5 file.
    pub scenario: String,
    pub duration_s: f64,
    pub clock: ClockMode,
    pub perception: PerceptionSource,
    pub set_speed_mps: f64,
    /// The ACC's time gap; None: its own setting.
    pub time_gap_s: Option<f64>,
    /// The vehicle the ACC drives (the scenario's ego); None: its own setting.
    pub vehicle: Option<VehicleClass>,
    /// Faults every node injects into what it receives (`--faults`); None: none.
    pub faults: Option<FaultProfile>,
    /// The links between the loop's processes (peer mode).
    pub link: LinkKind,
    /// Nodes of the user's own in the place of ours (`--controller`, `--detector`).
    pub own: OwnNodes,
    /// Several controlled vehicles ([`EgoNodes::of`] a scenario's `egos`): an ACC (and a
    /// detector with camera perception) per ego in its namespace, each with its own settings;
    /// empty: one ego in the run's namespace, set by the fields above.
    pub egos: Vec<EgoNodes>,
}

impl LoopSpec {
    /// The vehicle the ACC drives for a scenario: its ego's.
    pub fn vehicle_of(scenario: &slipstream_sim::Scenario) -> VehicleClass {
        slipstream_contract::msg::ObjectClass::from(scenario.ego().class).into()
    }

    /// The nodes a run of this loop brings onto the bus: its observer, the ACC, the detector
    /// with camera perception, and the simulator (which `up --sim external` does not start,
    /// and a re-simulation replaces with its observer).
    fn nodes<'a>(&'a self, observer: &'a str) -> Vec<&'a str> {
        let mut v = vec![observer, ACC_NODE, SIM_NODE];
        if self.perception == PerceptionSource::Camera {
            v.push(DETECT_NODE);
        }
        v.extend(self.own.others.iter().map(|o| o.node()));
        v
    }

    /// Faults a node of this loop cannot take: none can land in a node of the user's own (our
    /// nodes inject them as they receive), nor, in lockstep, [`refuse_in_lockstep`]'s.
    fn check_faults(&self) -> Result<()> {
        let Some(p) = &self.faults else { return Ok(()) };
        if let Some((topic, own)) = self.own.fault_into_foreign(p) {
            return Err(Error::Refused(format!(
                "{}: key `topics.{topic}`: its faults would land in a node of your own ({}, `{}`), which reads {topic}; faults are injected by slipstream's own nodes as they receive (fix: name only slipstream's nodes in the entry's `at` (sim, acc, detect: those this loop runs itself), or judge it without --faults)",
                p.name,
                own.node(),
                own.command_line()
            )));
        }
        match self.clock {
            ClockMode::Lockstep => refuse_in_lockstep(p),
            _ => Ok(()),
        }
    }
}

/// Faults a lockstep loop cannot take: every step waits for the ACC's answer to its speed
/// message and for the detections of its frame, so speed and camera frames must arrive; their
/// faults belong on what follows them.
pub fn refuse_in_lockstep(p: &FaultProfile) -> Result<()> {
    for (topic, instead) in [
        (slipstream_contract::topics::VEHICLE_SPEED.topic, "vehicle/state and vehicle/control"),
        (slipstream_contract::topics::CAMERA_FRONT.topic, "perception/objects (ground truth: objects)"),
    ] {
        if p.topics.contains_key(&topic) {
            return Err(Error::Refused(format!(
                "{}: key `topics.{topic}`: faults on {topic} cannot run in lockstep (each step waits for what follows from it) (fix: put them on {instead}, or use --mode realtime or fast)",
                p.name
            )));
        }
    }
    Ok(())
}

/// How the loop's processes find each other.
#[derive(Debug, Clone)]
pub enum Network<'a> {
    /// The user's connection and topic flags (see the module doc), in a namespace no other
    /// loop holds ([`super::namespace`]). `sim_elsewhere`: the simulator is someone else's
    /// (`up --sim external`), expected in the namespace.
    User { connect: &'a ConnectArgs, sim_elsewhere: bool },
    /// Loopback ports and a namespace of the run's own; the topic config file, if any.
    Isolated { topics: Option<PathBuf>, namespace: String },
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
    /// How often its restart policy started it again.
    #[serde(skip_serializing_if = "is_zero")]
    pub restarts: u32,
    pub log: PathBuf,
    /// Its stdout: the report of a node run with `--json`.
    #[serde(skip)]
    pub out: PathBuf,
}

impl NodeEnd {
    /// Why it ended, as [`why_it_ended`] reads it.
    pub fn why(&self) -> Option<String> {
        why_it_ended(&self.log, &self.out)
    }
}

/// What [`LoopRun::check`] saw.
#[derive(Debug, Clone, Default)]
pub struct Progress {
    /// The simulator has exited, with this status.
    pub sim_ended: Option<ExitStatus>,
    /// Nodes that ended before the run was over (the simulator too, if it failed).
    pub died: Vec<String>,
}

impl Progress {
    /// Nothing more to wait for.
    pub fn over(&self) -> bool {
        self.sim_ended.is_some() || !self.died.is_empty()
    }
}

/// The node binaries, in start order.
const ACC: &str = "slipstream-acc";
const DETECT: &str = "slipstream-detect";
const SIM: &str = "slipstream-sim";
/// Where a ROS 2 controller finds the ROS namespace its bridge uses.
const ROS_NAMESPACE_ENV: &str = "SLIPSTREAM_ROS_NAMESPACE";
/// The process of the bridge beside a ROS 2 controller.
const ROS2_BRIDGE: &str = "ros2-bridge";
/// The nodes' names on the bus (their liveliness tokens).
const ACC_NODE: &str = "acc";
const DETECT_NODE: &str = "detect";
const SIM_NODE: &str = "sim";
/// How long a simulator of the user's own may take to close by itself once its run is over.
const OWN_SIM_CLOSE: std::time::Duration = std::time::Duration::from_secs(2);

/// Whether a node process is the loop's simulator: ours, or the user's (its role's name).
/// Says on the terminal what `up` waits for instead of starting `node` (started elsewhere).
fn announce_elsewhere(node: &ForeignNode, ns: &str) {
    let ns = if ns.is_empty() { "the default namespace".to_string() } else { format!("namespace `{ns}`") };
    eprintln!(
        "waiting up to {} s for the {} started elsewhere: its token nodes/{} in {ns}",
        node.run.ready.timeout_s,
        node.process(),
        node.node()
    );
}

fn is_sim(process: &str) -> bool {
    process == SIM || process == Role::Simulator.process()
}

/// The file slipstream-sim --json writes its report to, in the logs directory.
const SIM_REPORT: &str = "slipstream-sim.json";
/// The file slipstream-acc --json writes its statistics to, in the logs directory.
const ACC_REPORT: &str = "slipstream-acc.json";
/// The file slipstream-detect --json writes its statistics to, in the logs directory.
const DETECT_REPORT: &str = "slipstream-detect.json";
/// The fault profile handed to the nodes, in the logs directory.
const FAULTS_FILE: &str = "faults.json5";

/// Zenoh settings of an isolated loop's sessions (the observer's and every node's). Each node
/// dials the observer and every node started before it, so the sessions form a full mesh
/// without gossip; with gossip on, a session's open waited out Zenoh's scouting delay (500 ms)
/// about every other time, for a peer connection gossip had made in parallel. A node whose
/// peer is not listening yet (they start together) dials again after 20 ms, not 250.
pub const ISOLATED_CFG: [(&str, &str); 2] = [
    ("scouting/gossip/enabled", "false"),
    ("connect/retry", "{period_init_ms: 20, period_max_ms: 2000, period_increase_factor: 2}"),
];

/// Where the observer and each node listen: loopback ports or unix sockets.
#[derive(Debug)]
struct Endpoints {
    observer: String,
    acc: String,
    detect: String,
    sim: String,
    /// Each node's low-latency session's endpoint, by its main endpoint.
    low_latency: Vec<(String, String)>,
    link: LinkKind,
    /// The unix sockets' directory (removed when the run ends).
    dir: Option<PathBuf>,
}

impl Endpoints {
    fn new(link: LinkKind) -> Result<Endpoints> {
        match link {
            LinkKind::Tcp => {
                let [observer, acc, detect, sim, acc_ll, detect_ll, sim_ll] =
                    free_ports::<7>()?.map(|p| format!("tcp/127.0.0.1:{p}"));
                let low_latency = vec![(acc.clone(), acc_ll), (detect.clone(), detect_ll), (sim.clone(), sim_ll)];
                Ok(Endpoints { observer, acc, detect, sim, low_latency, link, dir: None })
            }
            LinkKind::Unix => {
                // Short: a socket's path has at most 107 bytes.
                static RUNS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
                let run = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let dir = std::env::temp_dir().join(format!("slipstream-{}-{run}", std::process::id()));
                std::fs::create_dir_all(&dir).map_err(Error::file("create", &dir))?;
                let sock = |name: &str| format!("unixsock-stream/{}", dir.join(format!("{name}.sock")).display());
                let low_latency = [ACC, DETECT, SIM].iter().map(|n| (sock(n), format!("{}.ll", sock(n)))).collect();
                Ok(Endpoints {
                    observer: sock("observer"),
                    acc: sock(ACC),
                    detect: sock(DETECT),
                    sim: sock(SIM),
                    low_latency,
                    link,
                    dir: Some(dir),
                })
            }
        }
    }

    /// An endpoint for a node in no role of ours (`name`: letters, digits, - and _).
    fn extra(&self, name: &str) -> Result<String> {
        match (self.link, &self.dir) {
            (LinkKind::Unix, Some(dir)) => {
                Ok(format!("unixsock-stream/{}", dir.join(format!("other-{name}.sock")).display()))
            }
            _ => Ok(format!("tcp/127.0.0.1:{}", free_ports::<1>()?[0])),
        }
    }
}

impl Drop for Endpoints {
    fn drop(&mut self) {
        if let Some(dir) = &self.dir {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

/// The loop's processes and the observer's session.
pub struct LoopRun {
    bus: Bus,
    spec: LoopSpec,
    logs: PathBuf,
    /// Flags every node gets (config, topics, namespace, mode, ...).
    base_flags: Vec<String>,
    /// Endpoints the user gave with -e (peer mode: dialled besides the loop's own ports).
    user_connect: Vec<String>,
    /// Peer mode: each node listens on its own port and dials the ones before it.
    peer: bool,
    /// The run's network is its own ([`Network::Isolated`]): nobody else is on it.
    isolated: bool,
    endpoints: Endpoints,
    nodes: Vec<Supervised>,
    /// The endpoints of the nodes started so far: each new one dials them.
    started: Vec<String>,
    died: Vec<String>,
    /// See [`LoopRun::moved`].
    moved: Option<(String, String)>,
    /// The run's hold on its namespace on this machine, for as long as the run lasts.
    _hold: Option<super::hold::Hold>,
}

impl LoopRun {
    /// Joins the bus as `observer`, with the node logs going to `logs` (created). Nothing is
    /// started yet: subscribe to what you record first, then [`LoopRun::start`].
    pub async fn open(spec: LoopSpec, network: Network<'_>, logs: &Path, observer: &str) -> Result<LoopRun> {
        std::fs::create_dir_all(logs).map_err(Error::file("create the log directory", logs))?;
        let endpoints = Endpoints::new(spec.link)?;
        let isolated = matches!(network, Network::Isolated { .. });
        if let Some(node) = spec.own.elsewhere().filter(|_| isolated) {
            return Err(Error::Refused(format!(
                "the {} is started elsewhere: only `slipstream up` and `conform` without --command join a node started elsewhere (eval and `conform --command` run each loop in a namespace and on ports of their own, where no node of yours can be waiting); fix: give its command in the loop file, or use `up`",
                node.process()
            )));
        }
        let sim_elsewhere = matches!(network, Network::User { sim_elsewhere: true, .. });
        // Nodes of the user's started elsewhere wait in the namespace given: it cannot move.
        let expected_here = sim_elsewhere || spec.own.elsewhere().is_some();
        let (config, topic_map, mut base_flags, user_connect, peer) = match network {
            Network::User { connect, .. } => {
                let mut config = connect.zenoh_config()?;
                let mode = config.get_json("mode").ok().and_then(|m| serde_json::from_str::<String>(&m).ok());
                if mode.as_deref() == Some("router") {
                    return Err(Error::Refused("the loop runs its nodes as peers or clients, not routers (-m)".into()));
                }
                let peer = mode.as_deref().unwrap_or("peer") == "peer";
                if peer {
                    let mut listen: Vec<serde_json::Value> = config
                        .get_json("listen/endpoints")
                        .ok()
                        .and_then(|s| serde_json::from_str(&s).ok())
                        .unwrap_or_default();
                    listen.push(endpoints.observer.clone().into());
                    config
                        .insert_json5("listen/endpoints", &serde_json::Value::Array(listen).to_string())
                        .map_err(Error::zenoh("add a listen endpoint for the nodes"))?;
                }
                (config, connect.topic_map()?, user_flags(connect), connect.connect.clone(), peer)
            }
            Network::Isolated { topics, namespace } => {
                let mut config = zenoh::Config::from_json5(DEFAULT_ZENOH_CONFIG)
                    .map_err(Error::zenoh("the built-in Zenoh configuration"))?;
                config
                    .insert_json5("listen/endpoints", &format!("[\"{}\"]", endpoints.observer))
                    .map_err(Error::zenoh("listen on the observer's endpoint"))?;
                config.insert_json5("connect/endpoints", "[]").map_err(Error::zenoh("connect to nothing"))?;
                let map =
                    slipstream_contract::TopicMap::load_or_default(topics.as_deref())?.with_namespace(&namespace)?;
                let mut flags = vec!["-n".to_string(), namespace];
                for (key, value) in ISOLATED_CFG {
                    config.insert_json5(key, value).map_err(Error::zenoh(format!("zenoh config key {key}")))?;
                    flags.extend(["--cfg".into(), format!("{key}:{value}")]);
                }
                if let Some(file) = topics {
                    flags.extend(["-t".into(), file.display().to_string()]);
                }
                (config, map, flags, Vec::new(), true)
            }
        };
        let meeting = super::hold::meeting_point(&config, &endpoints.observer);
        let session = slipstream_contract::bus::open_session(config, "join the bus").await?;
        let claimed = match isolated {
            true => super::namespace::Claimed { map: topic_map, moved_to: None, beside: String::new(), hold: None },
            false => {
                let theirs: Vec<&str> = spec.own.foreign().filter(|n| n.elsewhere).map(|n| n.node()).collect();
                let ours: Vec<&str> = spec
                    .nodes(observer)
                    .into_iter()
                    .filter(|n| !(theirs.contains(n) || sim_elsewhere && *n == SIM_NODE))
                    .collect();
                super::namespace::claim(&session, topic_map, &ours, expected_here, &meeting).await?
            }
        };
        if let Some(ns) = &claimed.moved_to {
            base_flags.extend(["-n".into(), ns.clone()]);
        }
        let moved = claimed.moved_to.clone().map(|ns| (ns, claimed.beside.clone()));
        let hold = claimed.hold;
        let bus = Bus::from_session(session, claimed.map, observer).await?;
        Ok(LoopRun {
            bus,
            spec,
            logs: logs.to_path_buf(),
            base_flags,
            user_connect,
            peer,
            isolated,
            endpoints,
            nodes: Vec::new(),
            started: Vec::new(),
            died: Vec::new(),
            moved,
            _hold: hold,
        })
    }

    /// Set when the default namespace held another loop and this one moved: the namespace it
    /// moved to and why the default one was taken ([`super::namespace`]).
    pub fn moved(&self) -> Option<&(String, String)> {
        self.moved.as_ref()
    }

    /// The observer's session: subscribe here to what the run is judged by.
    pub fn bus(&self) -> &Bus {
        &self.bus
    }

    pub fn spec(&self) -> &LoopSpec {
        &self.spec
    }

    /// Where the nodes' logs go: `<node>.log` (stderr), `<node>.out` (stdout).
    pub fn logs(&self) -> &Path {
        &self.logs
    }

    fn camera(&self) -> bool {
        self.spec.perception == PerceptionSource::Camera
    }

    /// Starts the controllers, waits until they are alive on the bus (at most
    /// [`super::NODE_START_TIMEOUT`] unless the loop file says otherwise), then starts the
    /// simulator.
    pub async fn start(&mut self) -> Result<()> {
        self.start_controllers().await?;
        self.start_sim()
    }

    /// Starts the nodes in no role of ours (a loop file's `others`), the ACC (and the
    /// detector with camera perception) and waits until they are ready: what a replay drives
    /// in place of the simulator (`slipstream_eval::resim`).
    pub async fn start_controllers(&mut self) -> Result<()> {
        let spec = self.spec.clone();
        spec.check_faults()?;
        if let Some(p) = &spec.faults {
            let path = self.logs.join(FAULTS_FILE);
            std::fs::write(&path, p.to_json5()).map_err(Error::file("write", &path))?;
            self.base_flags.extend(["--faults".into(), path.display().to_string()]);
        }
        if !spec.egos.is_empty() {
            let waits = self.start_ego_controllers().await?;
            return self.await_ready(waits).await;
        }
        let mut waits = Vec::new();
        for node in &spec.own.others {
            let own = self.endpoints.extra(node.node())?;
            waits.push(self.watch(node.node(), node.process()).await?);
            self.spawn_foreign(node, &own)?;
        }
        let (acc, detect) = (self.endpoints.acc.clone(), self.endpoints.detect.clone());
        match &spec.own.controller {
            Some(node) => {
                waits.push(self.watch(ACC_NODE, node.process()).await?);
                self.spawn_foreign(node, &acc)?;
                if node.ros2 {
                    self.spawn_ros2_bridge()?
                }
            }
            None => {
                waits.push(self.watch(ACC_NODE, ACC).await?);
                self.spawn(ACC, self.acc_args(), &acc)?
            }
        }
        if self.camera() {
            match &spec.own.detector {
                Some(node) => {
                    waits.push(self.watch(DETECT_NODE, node.process()).await?);
                    self.spawn_foreign(node, &detect)?
                }
                None => {
                    waits.push(self.watch(DETECT_NODE, DETECT).await?);
                    self.spawn(DETECT, vec!["--json".into()], &detect)?
                }
            }
        }
        self.await_ready(waits).await
    }

    /// The bridge that puts a ROS 2 controller in the loop (a loop file's `controller.ros2`):
    /// `slipstream ros2 --control` as the node `acc`, answering lockstep steps by the stamps of
    /// the controller's commands and declaring its token once the controller's endpoints are
    /// in the ROS graph, so the loop's readiness and the simulator's lockstep need no change.
    fn spawn_ros2_bridge(&mut self) -> Result<()> {
        let own = self.endpoints.extra(ROS2_BRIDGE)?;
        // Faults land at our nodes as they receive; the bridge stands in for the controller.
        let flags = self.flags(&own);
        let mut flags = flags.into_iter();
        let mut kept = Vec::new();
        while let Some(f) = flags.next() {
            match f.as_str() {
                "--faults" => drop(flags.next()),
                _ => kept.push(f),
            }
        }
        let mut cmd = Command::new(sibling_binary("slipstream")?);
        cmd.args(kept).args(["ros2", "--control", "--json", "--name", ACC_NODE, "--clock", self.spec.clock.name()]);
        if let Some(v) = self.spec.vehicle {
            cmd.args(["--vehicle", v.name()]);
        }
        cmd.args(["--ros-namespace", &self.ros_namespace()]);
        self.launch(ROS2_BRIDGE, cmd, &format!("{ROS2_BRIDGE}.json"), &own)
    }

    /// The ROS namespace of a ROS 2 controller and its bridge (SLIPSTREAM_ROS_NAMESPACE): the
    /// bus's namespace as `/name` in `up`; the root in a run on a network of its own (eval,
    /// conform), which is apart already, under a namespace made for it.
    fn ros_namespace(&self) -> String {
        match self.bus.topics().namespace() {
            ns if self.isolated || ns.is_empty() => "/".into(),
            ns => format!("/{ns}"),
        }
    }

    /// slipstream-acc's flags for the spec.
    fn acc_args(&self) -> Vec<String> {
        self.acc_args_of(self.spec.set_speed_mps, self.spec.time_gap_s, self.spec.vehicle)
    }

    /// slipstream-acc's flags for one ego's settings.
    fn acc_args_of(&self, set_speed_mps: f64, time_gap_s: Option<f64>, vehicle: Option<VehicleClass>) -> Vec<String> {
        let spec = &self.spec;
        let mut acc_args = vec![
            "--json".to_string(),
            "--set-speed".into(),
            set_speed_mps.to_string(),
            "--perception".into(),
            spec.perception.name().into(),
        ];
        if let Some(h) = time_gap_s {
            acc_args.extend(["--time-gap".into(), h.to_string()]);
        }
        if let Some(v) = vehicle {
            acc_args.extend(["--vehicle".into(), v.name().into()]);
        }
        if spec.clock == ClockMode::Lockstep {
            acc_args.push("--lockstep".into());
        }
        acc_args
    }

    /// Starts the simulator, after [`LoopRun::start_controllers`].
    fn start_sim(&mut self) -> Result<()> {
        if self.spec.own.simulator.is_some() {
            return self.start_own_sim();
        }
        let spec = self.spec.clone();
        let sim = self.endpoints.sim.clone();
        let mut sim_args = vec![
            "--scenario".to_string(),
            spec.scenario.clone(),
            "--mode".into(),
            spec.clock.name().into(),
            "--duration".into(),
            spec.duration_s.to_string(),
            "--json".into(),
        ];
        if spec.clock == ClockMode::Lockstep {
            let others = spec.own.others.iter().filter(|o| o.run.lockstep).map(|o| o.node());
            let wait_for: Vec<&str> = std::iter::once(ACC_NODE).chain(others).collect();
            sim_args.extend(["--wait-for".into(), wait_for.join(",")]);
            // A controller of the user's own that stops answering ends its run at the first
            // step it leaves unanswered (a failed run either way), rather than costing every
            // step the timeout: a sweep over it finishes. One that is restarted on failure is
            // waited for: the steps it misses take the timeout policy and are counted.
            let restarts = |n: &ForeignNode| n.run.restart.policy == RestartPolicy::OnFailure;
            if spec.own.controller.as_ref().is_some_and(|n| !restarts(n)) {
                sim_args.extend(["--on-timeout".into(), "stop".into()]);
            }
        }
        self.spawn(SIM, sim_args, &sim)
    }

    /// Starts the simulator of the user's own a loop file names (its `simulator.command`);
    /// none, or one started elsewhere: nothing. The loop knows it by its messages
    /// ([`super::ExternalSim`]), as with `up --sim external`.
    pub fn start_own_sim(&mut self) -> Result<()> {
        match self.spec.own.simulator.clone() {
            Some(node) if !node.elsewhere => {
                let sim = self.endpoints.sim.clone();
                self.spawn_foreign(&node, &sim)
            }
            _ => Ok(()),
        }
    }

    /// Watches for a node about to start to become ready, as its loop file entry says.
    async fn watch(&self, node: &str, process: &str) -> Result<super::ready::Watch> {
        super::ready::Watch::new(&self.bus, node, process, &self.spec.own.run_of(process).ready).await
    }

    /// The simulator's first frame must find every node ready (listening).
    async fn await_ready(&mut self, waits: Vec<super::ready::Watch>) -> Result<()> {
        let seen = self.watch_all_nodes().await?;
        let nodes = &mut self.nodes;
        let ended = || {
            for n in nodes.iter_mut() {
                if let State::Ended(status) = n.poll() {
                    let why = why_it_ended(&n.log, &n.out).map_or(String::new(), |e| format!(": {e}"));
                    let problem = format!("exited at start ({status}){why}\n(its log: {})", n.log.display());
                    return Err(Error::node(n.name(), problem));
                }
            }
            Ok(())
        };
        super::ready::until_ready(&waits, || seen.names(), ended, &self.logs).await
    }

    /// The flags of one node: the shared ones, then its own endpoint and the ones it dials
    /// (the observer's and every node's started before it). Its low-latency session listens
    /// on an endpoint of its own and dials the observer's (main) session and the earlier
    /// nodes' low-latency sessions, so the loop's real-time topics cross low-latency links
    /// and the observer still receives them.
    fn flags(&self, own: &str) -> Vec<String> {
        let mut f = self.base_flags.clone();
        if self.peer {
            f.extend(["-l".into(), own.to_string()]);
            for e in std::iter::once(&self.endpoints.observer).chain(&self.started) {
                f.extend(["-e".into(), e.to_string()]);
            }
            let ll = |main: &str| self.endpoints.low_latency.iter().find(|(m, _)| m == main).map(|(_, l)| l.clone());
            let two_sessions = self.base_flags.iter().any(|f| f == "--low-latency-session");
            if let Some(own_ll) = ll(own).filter(|_| two_sessions) {
                f.extend(["--low-latency-listen".into(), own_ll]);
                f.extend(["--low-latency-connect".into(), self.endpoints.observer.clone()]);
                for e in self.started.iter().filter_map(|e| ll(e)) {
                    f.extend(["--low-latency-connect".into(), e]);
                }
                for e in &self.user_connect {
                    f.extend(["--low-latency-connect".into(), e.clone()]);
                }
            }
        }
        for e in &self.user_connect {
            f.extend(["-e".into(), e.clone()]);
        }
        f
    }

    /// One of our nodes, with what the loop file adds (arguments after the loop's, its
    /// environment).
    fn spawn(&mut self, bin: &str, args: Vec<String>, own: &str) -> Result<()> {
        let stdout_name = match bin {
            SIM => SIM_REPORT.to_string(),
            ACC => ACC_REPORT.to_string(),
            DETECT => DETECT_REPORT.to_string(),
            _ => format!("{bin}.out"),
        };
        let cmd = self.command_of(bin, args, self.flags(own))?;
        self.launch(bin, cmd, &stdout_name, own)
    }

    /// The command of one of our node binaries: `flags`, then `args`, then what the loop file
    /// adds for that role.
    fn command_of(&self, bin: &str, args: Vec<String>, flags: Vec<String>) -> Result<Command> {
        let b = &self.spec.own.builtin;
        let file_args = match bin {
            SIM => b.simulator.as_ref(),
            ACC => b.controller.as_ref(),
            _ => b.detector.as_ref(),
        }
        .map(|n| n.args.clone())
        .unwrap_or_default();
        let mut cmd = Command::new(sibling_binary(bin)?);
        cmd.args(flags).args(args).args(file_args);
        Ok(cmd)
    }

    /// A node of the user's own, under its process name (`controller.log`, `controller.out`).
    fn spawn_foreign(&mut self, node: &ForeignNode, own: &str) -> Result<()> {
        let name = node.process().to_string();
        if node.elsewhere {
            announce_elsewhere(node, self.bus.topics().namespace());
            return Ok(());
        }
        let run = [self.spec.clock.name(), self.spec.perception.name()];
        let mut cmd = node.command(&self.flags(own), &self.logs, run)?;
        if node.ros2 {
            cmd.env(ROS_NAMESPACE_ENV, self.ros_namespace());
        }
        self.launch(&name, cmd, &format!("{name}.out"), own)
    }

    /// Starts a node process as `name` ([`Supervised`]): stderr to its log (the loop file's
    /// `log`, else `<name>.log` in the logs directory), stdout to `stdout_name` there; `own` is
    /// its endpoint, which the nodes started after it dial.
    fn launch(&mut self, name: &str, cmd: Command, stdout_name: &str, own: &str) -> Result<()> {
        let run = self.spec.own.run_of(name);
        self.launch_as(name, run, cmd, stdout_name, own)
    }

    /// [`Self::launch`] with the loop file's settings `run` given (a role's, for one ego's node).
    fn launch_as(&mut self, name: &str, run: NodeRun, cmd: Command, stdout_name: &str, own: &str) -> Result<()> {
        let log = run.log.as_ref().map_or_else(|| log_of(&self.logs, name), |l| self.logs.join(l));
        if let Some(dir) = log.parent() {
            std::fs::create_dir_all(dir).map_err(Error::file("create", dir))?;
        }
        self.nodes.push(Supervised::start(name, cmd, run, log, self.logs.join(stdout_name))?);
        self.started.push(own.to_string());
        Ok(())
    }

    /// Whether the simulator has ended and which nodes died (each named once, when first
    /// seen; a node restarted by its policy has not died).
    pub fn check(&mut self) -> Progress {
        let mut progress = Progress::default();
        for n in &mut self.nodes {
            let State::Ended(status) = n.poll() else { continue };
            if is_sim(n.name()) {
                progress.sim_ended = Some(status);
                if status.success() {
                    continue;
                }
            }
            if !self.died.iter().any(|d| d == n.name()) {
                self.died.push(n.name().to_string());
            }
        }
        progress.died = self.died.clone();
        progress
    }

    /// A node's stderr log, by its process name.
    pub fn log(&self, name: &str) -> PathBuf {
        self.nodes.iter().find(|n| n.name() == name).map_or_else(|| log_of(&self.logs, name), |n| n.log.clone())
    }

    /// Why the node `name` ended, as [`why_it_ended`] reads it from its report and its log.
    pub fn why_ended(&self, name: &str) -> Option<String> {
        match self.nodes.iter().find(|n| n.name() == name) {
            Some(n) => why_it_ended(&n.log, &n.out),
            None => last_words(&log_of(&self.logs, name)),
        }
    }

    /// Stops the simulator first (it publishes the scenario's end), then the others, and waits
    /// [`SETTLE`] for the last messages. Returns how each node ended.
    pub async fn stop(&mut self) -> Vec<NodeEnd> {
        if let Some(sim) = self.nodes.iter_mut().find(|n| is_sim(n.name())) {
            // A simulator of the user's own ends its run by itself after publishing its end
            // (the loop stops on that message, the process is still closing): a signal then
            // would cut its close short. Ours has written its report before its end.
            if sim.name() != SIM {
                sim.wait_for(OWN_SIM_CLOSE);
            }
            sim.stop(STOP_GRACE);
        }
        // What the controllers say after the simulator's end is not judged: they stop while
        // the simulator's last messages land.
        for n in &mut self.nodes {
            n.interrupt();
        }
        tokio::time::sleep(SETTLE).await;
        for n in &mut self.nodes {
            n.stop(STOP_GRACE);
        }
        let died = self.died.clone();
        self.nodes
            .iter_mut()
            .map(|n| NodeEnd {
                node: n.name().to_string(),
                pid: n.pid(),
                exit_code: n.exited().and_then(|s| s.code()),
                died: died.iter().any(|d| d == n.name()),
                restarts: n.restarts,
                log: n.log.clone(),
                out: n.out.clone(),
            })
            .collect()
    }

    /// The node processes started so far: (binary name, pid).
    pub fn node_pids(&self) -> Vec<(String, u32)> {
        self.nodes.iter().map(|n| (n.name().to_string(), n.pid())).collect()
    }

    /// The simulator's report (its --json output), once it has ended.
    pub fn sim_report(&self) -> Result<SimReport> {
        let path = self.logs.join(SIM_REPORT);
        let bytes = std::fs::read(&path).map_err(Error::file("read", &path))?;
        serde_json::from_slice(&bytes).map_err(|source| Error::Json { path, what: "is no simulator report", source })
    }

    /// The ACC's statistics (its --json output), once it has been stopped.
    pub fn acc_report(&self) -> Result<AccStats> {
        let path = self.logs.join(ACC_REPORT);
        let bytes = std::fs::read(&path).map_err(Error::file("read", &path))?;
        serde_json::from_slice(&bytes).map_err(|source| Error::Json { path, what: "holds no ACC statistics", source })
    }

    /// The detector's statistics (its --json output), once it has been stopped; None without
    /// camera perception.
    pub fn detect_report(&self) -> Result<Option<DetectStats>> {
        if !self.camera() || self.spec.own.detector.is_some() {
            return Ok(None);
        }
        let path = self.logs.join(DETECT_REPORT);
        let bytes = std::fs::read(&path).map_err(Error::file("read", &path))?;
        serde_json::from_slice(&bytes).map(Some).map_err(|source| Error::Json {
            path,
            what: "holds no detector statistics",
            source,
        })
    }

    /// The inputs of the ACC and the simulator as they ended (after [`LoopRun::stop`]): what
    /// was lost on the way and what the faults injected. Empty for a node whose report is
    /// missing.
    pub fn inputs(&self) -> Vec<NodeInput> {
        let mut v: Vec<NodeInput> = self
            .acc_report()
            .map(|a| a.inputs.into_iter().map(|stats| NodeInput { node: ACC_NODE.into(), stats }).collect())
            .unwrap_or_default();
        if let Ok(sim) = self.sim_report() {
            v.push(NodeInput { node: SIM_NODE.into(), stats: sim.control_input });
        }
        v
    }

    /// Leaves the bus ([`Bus::leave`]: bounded, never failing): other sessions still attached
    /// (a `top`, a Python client) must not hold up the caller's report.
    pub async fn close(self) {
        self.bus.leave().await;
    }
}

/// A node's stderr log in `logs`.
pub fn log_of(logs: &Path, node: &str) -> PathBuf {
    logs.join(format!("{node}.log"))
}

/// How far back from its end a node's log is read for its error.
const ERROR_TAIL_BYTES: u64 = 16 * 1024;

/// The last error printed in `tail`: after "Error: ", with its "caused by" lines, as every
/// binary prints them (`cli::error_report`); None when there is none.
fn error_in(tail: &str) -> Option<String> {
    let lines: Vec<&str> = tail.lines().collect();
    let at = lines.iter().rposition(|l| l.starts_with("Error: "))?;
    let first = lines[at].trim_start_matches("Error: ");
    let error: Vec<&str> =
        std::iter::once(first).chain(lines[at + 1..].iter().copied().take_while(|l| l.starts_with("  "))).collect();
    Some(error.join("\n"))
}

/// Why a node ended: the failure its JSON report holds (`report`, its stdout: every node of
/// ours run with `--json` writes one, `slipstream_contract::node::Failure`), else what its log
/// says last ([`last_words`]: a program that writes no report).
pub fn why_it_ended(log: &Path, report: &Path) -> Option<String> {
    let failed = std::fs::read(report).ok().and_then(|bytes| slipstream_contract::node::Failure::in_report(&bytes));
    failed.map(|f| f.line()).or_else(|| last_words(log))
}

/// What a node said last about why it stopped: its error (`error_in`), else the last line
/// of its log (a Python traceback ends with the exception), if any.
pub fn last_words(log: &Path) -> Option<String> {
    let tail = log_tail(log)?;
    error_in(&tail).or_else(|| tail.lines().rev().find(|l| !l.trim().is_empty()).map(|l| l.trim().to_string()))
}

/// The last [`ERROR_TAIL_BYTES`] of a log.
fn log_tail(log: &Path) -> Option<String> {
    use std::io::{Read, Seek, SeekFrom};
    let mut file = std::fs::File::open(log).ok()?;
    let len = file.metadata().ok()?.len();
    file.seek(SeekFrom::Start(len.saturating_sub(ERROR_TAIL_BYTES))).ok()?;
    let mut bytes = Vec::new();
    file.take(ERROR_TAIL_BYTES).read_to_end(&mut bytes).ok()?;
    Some(String::from_utf8_lossy(&bytes).into_owned())
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// The user's flags as the nodes take them (endpoints are added per node).
fn user_flags(connect: &ConnectArgs) -> Vec<String> {
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
    if connect.low_latency_session {
        base.push("--low-latency-session".into());
    }
    base
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn why_a_node_ended_is_its_reports_failure_else_its_logs_last_words() {
        let dir = std::env::temp_dir().join(format!("slipstream-why-ended-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (log, out) = (dir.join("acc.log"), dir.join("acc.out"));
        std::fs::write(&log, "INFO acc up\nError: acc: run\n  caused by: the bus closed\nzenoh says goodbye\n")
            .unwrap();
        std::fs::write(&out, r#"{"error": "acc: run", "causes": ["settings: bad"]}"#).unwrap();
        assert_eq!(why_it_ended(&log, &out).as_deref(), Some("acc: run: settings: bad"));
        std::fs::write(&out, r#"{"commands": 3}"#).unwrap();
        assert_eq!(why_it_ended(&log, &out).as_deref(), Some("acc: run\n  caused by: the bus closed"));
        std::fs::remove_file(&out).unwrap();
        std::fs::write(&log, "Traceback (most recent call last):\n  ...\nValueError: no speed\n").unwrap();
        assert_eq!(why_it_ended(&log, &out).as_deref(), Some("ValueError: no speed"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
