//! One platoon run on the bus: slipstream-sim (in lockstep, or on the wall clock) on the
//! scenario rewritten to start in the equilibrium of the time gap asked, and per ego in its
//! namespace a slipstream-acc (and a slipstream-detect with camera perception), all child
//! processes in a namespace of the run's own, linked as [`Links`] says (directly on loopback,
//! or through a router). The launcher's observer records each car's vehicle/state and the
//! leader's speed from the first car's ground truth.

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use serde_json::Value;

use super::figures::CarSeries;
use super::links::Links;
use crate::error::{Error, Result};
use slipstream_acc::PerceptionSource;
use slipstream_contract::config::{parse_json5_value, FaultArgs};
use slipstream_contract::msg::{GroundTruthObjects, VehicleState};
use slipstream_contract::{topics, Bus};
use slipstream_launch::child::{free_ports, sibling_binary, Child};
use slipstream_launch::foreign::Ready;
use slipstream_launch::ready::{until_ready, Watch};
use slipstream_launch::AllNodes;
use slipstream_model::vehicle::VehicleParams;
use slipstream_observe::latency::{LatencyWatch, WHOLE_LOOP};
use slipstream_sim::scenario::{ClassSpec, SEVERAL_EGOS};
use slipstream_sim::{Scenario, SimReport};

/// The longest a run may take in wall time per simulated second (lockstep on a loaded
/// machine), before it is stopped as stuck.
const WALL_PER_SIM_S: f64 = 6.0;

/// What one run recorded.
pub struct PlatoonRun {
    pub leader: CarSeries,
    pub cars: Vec<CarSeries>,
    pub sim: SimReport,
    /// The first car's loop latency in wall-clock time (frame or ground truth published ->
    /// its command applied), p99, seconds: measured in realtime only, where it delays the car.
    pub loop_p99_s: Option<f64>,
}

/// A platoon scenario as JSON: a built-in one by name, or a file.
pub(crate) fn scenario_value(name_or_path: &str) -> Result<Value> {
    let text = match SEVERAL_EGOS.iter().find(|(n, _)| *n == name_or_path) {
        Some((_, text)) => text.to_string(),
        None => std::fs::read_to_string(name_or_path).map_err(|e| {
            let built_in: Vec<&str> = SEVERAL_EGOS.iter().map(|(n, _)| *n).collect();
            Error::Refused(format!(
                "--scenario {name_or_path}: not a built-in platoon ({}) nor a file it can read: {e}",
                built_in.join(", ")
            ))
        })?,
    };
    Ok(parse_json5_value(&text, name_or_path)?)
}

/// The scenario with its egos and its leader placed `standstill_m + time_gap_s x speed`
/// apart bumper to bumper, each ego's controller set to `time_gap_s` (and its duration
/// `duration_s` when given): every run starts in the equilibrium of the gap it measures, so the
/// only disturbance is the leader's. Returns the scenario and its text for slipstream-sim.
pub(crate) fn at_time_gap(
    mut value: Value,
    time_gap_s: f64,
    standstill_m: f64,
    duration_s: Option<f64>,
) -> Result<(Scenario, String)> {
    let origin = format!("platoon at {time_gap_s} s");
    let egos = value["egos"]
        .as_array_mut()
        .ok_or_else(|| Error::Refused("--scenario: a platoon lists its cars in `egos`".into()))?;
    let class = |e: &Value| -> VehicleParams {
        let c: ClassSpec = serde_json::from_value(e["class"].clone()).unwrap_or_default();
        VehicleParams::of_class(c.into())
    };
    let gap = |v: f64| standstill_m + time_gap_s * v;
    for k in 1..egos.len() {
        let (ahead, me) = (class(&egos[k - 1]), class(&egos[k]));
        let ahead_rear = egos[k - 1]["s_m"].as_f64().unwrap_or(50.0) - ahead.rear_overhang_m;
        let v = egos[k]["speed_mps"].as_f64().unwrap_or(0.0);
        egos[k]["s_m"] = (ahead_rear - gap(v) - me.size_m[0] + me.rear_overhang_m).into();
    }
    for e in egos.iter_mut() {
        e["time_gap_s"] = time_gap_s.into();
    }
    let v0 = egos[0]["speed_mps"].as_f64().unwrap_or(0.0);
    if let Some(leader) = value["traffic"].get_mut(0) {
        leader["gap_m"] = gap(v0).into();
    }
    if let Some(d) = duration_s {
        value["duration_s"] = d.into();
    }
    let text =
        serde_json::to_string_pretty(&value).map_err(|e| Error::Bug(format!("the platoon at {time_gap_s} s: {e}")))?;
    Ok((Scenario::parse(&text, &origin)?, text))
}

/// When the leader's disturbance begins: its first scripted action's time (0 without one).
pub fn disturbance_s(scenario: &Scenario) -> f64 {
    let actions = scenario.traffic.first().map(|t| t.actions.as_slice()).unwrap_or_default();
    actions.iter().filter_map(|a| a.at_s).fold(f64::INFINITY, f64::min).min(scenario.duration_s).max(0.0)
}

/// How a run's nodes are started: their perception, the fault profile file each injects (when
/// given), how they reach each other, and the simulator's clock (realtime: the loop's latency
/// delays every car as on the road; else lockstep).
pub struct Nodes<'a> {
    pub perception: PerceptionSource,
    pub faults: Option<&'a Path>,
    pub links: &'a Links,
    pub realtime: bool,
}

/// Runs `scenario` (written to `file`) once with every ego's nodes; records the speeds.
pub async fn run(scenario: &Scenario, file: &Path, nodes_of: &Nodes<'_>, dir: &Path) -> Result<PlatoonRun> {
    let (perception, faults, realtime) = (nodes_of.perception, nodes_of.faults, nodes_of.realtime);
    std::fs::create_dir_all(dir).map_err(|source| Error::File { action: "create", path: dir.into(), source })?;
    let ns = format!("platoon-{}-{}", std::process::id(), dir.file_name().and_then(|n| n.to_str()).unwrap_or("run"));
    let [port] = free_ports::<1>()?;
    let here = format!("tcp/127.0.0.1:{port}");
    let connect = nodes_of.links.observer(&ns, &here);
    let links = nodes_of.links.node_args(&here);
    let observer = Bus::open_node(&connect, &FaultArgs::default(), "platoon-eval").await?;
    let (cars, leader, _subs) = record(&observer, scenario).await?;
    let mut nodes = Vec::new();
    for ego in scenario.egos() {
        let car_ns = format!("{ns}/{}", ego.namespace.as_deref().unwrap_or_default());
        // Named as the car's processes are (car1-acc.log), so a log names its car.
        let log = |what: &str| dir.join(format!("{}.log", car_node(ego.namespace.as_deref(), what).1));
        let mut acc = node("slipstream-acc", &car_ns, &links, &log("acc"), faults)?;
        if !realtime {
            acc.arg("--lockstep");
        }
        acc.args(["--perception", perception.name(), "--set-speed"])
            .arg(ego.controller_set_speed_mps().to_string())
            .arg("--time-gap")
            .arg(ego.time_gap_s.unwrap_or(1.8).to_string());
        nodes.push(Child::spawn(&car_node(ego.namespace.as_deref(), "acc").1, &mut acc)?);
        if perception == PerceptionSource::Camera {
            let mut detect = node("slipstream-detect", &car_ns, &links, &log("detect"), faults)?;
            nodes.push(Child::spawn(&car_node(ego.namespace.as_deref(), "detect").1, &mut detect)?);
        }
    }
    let mut latency = None;
    if realtime {
        let first = observer.scoped(scenario.egos()[0].namespace.as_deref().unwrap_or_default())?;
        latency = Some(LatencyWatch::start(&first, perception == PerceptionSource::Camera).await?);
        nodes_up(&observer, scenario, perception, &mut nodes, dir).await?;
    }
    let report = dir.join("sim.json");
    let mut sim = node("slipstream-sim", &ns, &links, &dir.join("sim.log"), faults)?;
    sim.args(["--mode", if realtime { "realtime" } else { "lockstep" }, "--json", "--scenario"]).arg(file);
    sim.stdout(create(&report)?);
    let mut sim = Child::spawn("slipstream-sim", &mut sim)?;
    let per_sim_s = if realtime { 1.5 } else { WALL_PER_SIM_S };
    let limit = Duration::from_secs_f64(60.0 + scenario.duration_s * per_sim_s);
    let ended = tokio::task::block_in_place(|| sim.wait_for(limit));
    for n in &mut nodes {
        n.stop(Duration::from_secs(5));
    }
    if ended.is_none() {
        let problem = format!("did not end within {limit:?} (logs in {})", dir.display());
        return Err(Error::Node { node: "slipstream-sim".into(), problem });
    }
    let text = std::fs::read_to_string(&report).map_err(|source| Error::File {
        action: "read",
        path: report.clone(),
        source,
    })?;
    let sim: SimReport = serde_json::from_str(&text).map_err(|source| Error::Json {
        path: dir.join("sim.log"),
        what: "is the log of a simulator that wrote no report",
        source,
    })?;
    let cars = cars.iter().map(|c| c.lock().clone()).collect();
    let leader = leader.lock().clone();
    let loop_p99_s = latency.and_then(|l| l.latency.lock().stats(false)[WHOLE_LOOP].p99_ms).map(|ms| ms / 1e3);
    Ok(PlatoonRun { leader, cars, sim, loop_p99_s })
}

/// Waits until every car's ACC (and detector with the camera) is up, as `up` waits for its
/// nodes (each one's token within the launch layer's start timeout; a node that ends first is
/// named at once): in realtime the simulator does not wait for them, and a car without its
/// controller for the first seconds would be a disturbance of its own.
async fn nodes_up(
    observer: &Bus,
    scenario: &Scenario,
    perception: PerceptionSource,
    nodes: &mut [Child],
    dir: &Path,
) -> Result<()> {
    // A platoon of one ego may leave it in the run's own namespace: its nodes are `acc`, `detect`.
    let namespaces: Vec<String> = scenario.egos().iter().filter_map(|e| e.namespace.clone()).collect();
    let seen = AllNodes::watch(observer, &namespaces).await?;
    let wanted: &[&str] = if perception == PerceptionSource::Camera { &["acc", "detect"] } else { &["acc"] };
    let mut waits = Vec::new();
    for ego in scenario.egos() {
        for node in wanted {
            let (name, process) = car_node(ego.namespace.as_deref(), node);
            waits.push(Watch::new(observer, &name, &process, &Ready::default()).await?);
        }
    }
    let ended = || match nodes.iter_mut().find_map(|n| n.exited().map(|s| (n.name.clone(), s))) {
        Some((name, status)) => {
            let problem = format!("exited at start ({status}); its log is in {}", dir.display());
            Err(slipstream_launch::Error::Node { node: name, problem })
        }
        None => Ok(()),
    };
    Ok(until_ready(&waits, || seen.names(), ended, dir).await?)
}

/// A node's command: in `ns`, with the connection flags `links`, its log to `log`, injecting
/// the faults of the profile file `faults`.
/// A car's node as the bus knows it (`car1/acc`) and its process (`car1-acc`); a platoon of
/// one ego may leave it in the run's own namespace, where both are the plain name (`acc`).
fn car_node(namespace: Option<&str>, node: &str) -> (String, String) {
    match namespace {
        Some(ns) => (format!("{ns}/{node}"), format!("{ns}-{node}")),
        None => (node.to_string(), node.to_string()),
    }
}

fn node(binary: &str, ns: &str, links: &[String], log: &Path, faults: Option<&Path>) -> Result<Command> {
    let mut cmd = Command::new(sibling_binary(binary)?);
    cmd.args(["-n", ns]).args(links);
    if let Some(file) = faults {
        cmd.arg("--faults").arg(file);
    }
    cmd.stdout(std::process::Stdio::null()).stderr(create(log)?);
    Ok(cmd)
}

fn create(path: &Path) -> Result<std::fs::File> {
    std::fs::File::create(path).map_err(|source| Error::File { action: "create", path: path.into(), source })
}

type Shared = Arc<Mutex<CarSeries>>;

/// Subscriptions to each ego's vehicle/state and the first ego's ground truth (the leader, the
/// first scripted vehicle, is vehicle `egos.len()`).
async fn record(
    observer: &Bus,
    scenario: &Scenario,
) -> Result<(Vec<Shared>, Shared, Vec<slipstream_contract::bus::CallbackSubscriber>)> {
    let mut cars = Vec::new();
    let mut subs = Vec::new();
    for ego in scenario.egos() {
        let name = ego.namespace.clone().unwrap_or_default();
        let car: Shared = Arc::new(Mutex::new(CarSeries { name, samples: Vec::new() }));
        let scoped = observer.scoped(ego.namespace.as_deref().unwrap_or_default())?;
        let c = car.clone();
        subs.push(
            scoped
                .subscribe_with(topics::VEHICLE_STATE, move |r: slipstream_contract::bus::Received<VehicleState>| {
                    let t = r.header.stamp_sim_ns as f64 / 1e9;
                    c.lock().samples.push((t, r.msg.speed_mps, r.msg.acceleration_in_body_mps2[0]));
                })
                .await?,
        );
        cars.push(car);
    }
    let leader: Shared = Arc::new(Mutex::new(CarSeries { name: "leader".into(), samples: Vec::new() }));
    let (l, id) = (leader.clone(), scenario.egos().len() as u32);
    let first = observer.scoped(scenario.ego().namespace.as_deref().unwrap_or_default())?;
    subs.push(
        first
            .subscribe_with(topics::OBJECTS, move |r: slipstream_contract::bus::Received<GroundTruthObjects>| {
                let Some(o) = r.msg.objects.iter().find(|o| o.id == id) else { return };
                let (t, v) =
                    (r.header.stamp_sim_ns as f64 / 1e9, o.velocity_in_world_mps[0].hypot(o.velocity_in_world_mps[1]));
                let mut s = l.lock();
                let a = s.samples.last().filter(|p| t > p.0).map_or(0.0, |p| (v - p.1) / (t - p.0));
                s.samples.push((t, v, a));
            })
            .await?,
    );
    Ok((cars, leader, subs))
}
