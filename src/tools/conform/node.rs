//! `slipstream conform controller` and `conform detector`: a node of the user's own checked
//! against its contract (docs/node-contract.md) beside the reference simulator. With a
//! command, the node runs in its role of a short lockstep loop on loopback ports and a
//! namespace of its own; without one, the node already running is awaited on the user's
//! connection and namespace, as a loop awaits a node started elsewhere, so a node on another
//! PC, in a container or under a debugger is checked where it runs. Either way
//! slipstream-sim (and slipstream-acc beside a detector) runs with a 10 s readiness timeout
//! and stops at the first unanswered step, so a broken node costs seconds; every answer it
//! publishes is kept with its header and attachment and judged rule by rule against the
//! states and frames it answers.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use std::sync::Arc;

use super::rules::{Outcome, Verdict};
use super::ConformReport;
use crate::acc::PerceptionSource;
use crate::bus::{CallbackSubscriber, Received};
use crate::launch::foreign::{NodeRun, Role as LoopRole};
use crate::launch::{ClockMode, ForeignNode, LoopRun, LoopSpec, Network, OwnNodeArgs, OwnNodes, NODE_POLL};
use crate::msg::{ControlCommand, Detections, GroundTruthObjects, VehicleState};
use crate::topics;

/// How long a node may take to declare its token here.
const READY_S: f64 = 10.0;

/// `conform controller` / `conform detector`'s command line.
#[derive(clap::Args, Debug, Clone)]
pub struct ConformNodeArgs {
    /// The node's command line, split as a shell would (no shell runs it), started as the
    /// loop starts a node of your own (docs/own-node.md) [default: the node already running
    /// in the namespace (-n) on the connection (-e/-l), awaited up to 10 s]
    #[arg(long = "command", value_name = "CMD")]
    pub command: Option<String>,
    /// Where the controller's objects come from: ground truth (the simulator's `objects`) or
    /// the camera (slipstream-detect's `perception/objects`); a running controller must read
    /// the same (SLIPSTREAM_PERCEPTION) [default: ground-truth; camera for a detector]
    #[arg(long, value_enum)]
    pub perception: Option<PerceptionSource>,
    /// The scenario it runs in (a built-in name or a .json5 file)
    #[arg(long, default_value = "cut-in")]
    pub scenario: String,
    /// Simulated seconds to run
    #[arg(long, default_value_t = 5.0, value_parser = crate::tools::top::positive)]
    pub duration: f64,
    /// Print the verdicts as JSON
    #[arg(long)]
    pub json: bool,
}

/// Which contract is checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Controller,
    Detector,
}

/// What the loop's observer kept of the run.
#[derive(Default)]
struct Seen {
    states: Vec<Received<VehicleState>>,
    answers: Vec<Received<ControlCommand>>,
    frames: Vec<Received<GroundTruthObjects>>,
    detections: Vec<Received<Detections>>,
    statuses: usize,
    /// Payloads on the node's output that did not decode (garbage, another message type).
    undecodable: u64,
}

/// Runs the node in its role (started from its command, or the one already running on
/// `connect`) and judges what it did.
pub async fn run_node(
    role: Role,
    args: &ConformNodeArgs,
    connect: &crate::ConnectArgs,
) -> anyhow::Result<ConformReport> {
    let scenario = crate::sim::Scenario::find(&args.scenario)?;
    let spec = LoopSpec {
        scenario: args.scenario.clone(),
        duration_s: args.duration,
        clock: ClockMode::Lockstep,
        perception: perception(role, args)?,
        set_speed_mps: scenario.ego().controller_set_speed_mps(),
        time_gap_s: scenario.ego().time_gap_s,
        vehicle: Some(LoopSpec::vehicle_of(&scenario)),
        faults: None,
        link: Default::default(),
        own: nodes(role, args)?,
        egos: Vec::new(),
    };
    let pid = std::process::id();
    let logs = std::env::temp_dir().join(format!("slipstream-conform-{pid}"));
    let network = match args.command {
        Some(_) => Network::Isolated { topics: None, namespace: format!("conform-{pid}") },
        None => Network::User { connect, sim_elsewhere: false },
    };
    let mut lp = LoopRun::open(spec, network, &logs, "conform").await?;
    let namespace = lp.bus().topics().namespace().to_string();
    let (seen, subs) = watch(&lp).await?;
    let tokens = lp.bus().watch_nodes().await?;
    let started = lp.start().await;
    let (timeouts, ended) = match &started {
        Ok(()) => run_to_end(&mut lp, args.duration).await,
        Err(_) => (0, None),
    };
    let kept = tokens.names().iter().any(|n| n == role.node());
    let mut seen = std::mem::take(&mut *seen.lock());
    let output = match role {
        Role::Controller => &subs[1],
        Role::Detector => &subs[3],
    };
    seen.undecodable = output.stats().snapshot().decode_errors;
    let ends = lp.stop().await;
    lp.close().await;
    let mut verdicts = vec![token(role, &started, kept)];
    if let Some(died) = ends.iter().find(|e| e.died) {
        verdicts.push(died_verdict(died));
    }
    if started.is_ok() {
        verdicts.extend(match role {
            Role::Controller => judge_controller(&seen, timeouts, ended.as_deref()),
            Role::Detector => judge_detector(&seen),
        });
    }
    let pass = !super::failed(&verdicts);
    let subject = match role {
        Role::Controller => "controller",
        Role::Detector => "detector",
    };
    Ok(ConformReport { subject, namespace, lockstep: true, window_s: args.duration, pass, verdicts })
}

/// The node under test in its role: started from its command, or awaited where it runs.
fn nodes(role: Role, args: &ConformNodeArgs) -> anyhow::Result<OwnNodes> {
    let Some(command) = &args.command else {
        let mut run = NodeRun::default();
        run.ready.timeout_s = READY_S;
        let node = match role {
            Role::Controller => ForeignNode::started_elsewhere(LoopRole::Controller, None, run),
            Role::Detector => ForeignNode::started_elsewhere(LoopRole::Detector, None, run),
        };
        return Ok(match role {
            Role::Controller => OwnNodes { controller: Some(node), ..Default::default() },
            Role::Detector => OwnNodes { detector: Some(node), ..Default::default() },
        });
    };
    let flags = match role {
        Role::Controller => OwnNodeArgs { controller: Some(command.clone()), ..Default::default() },
        Role::Detector => OwnNodeArgs { detector: Some(command.clone()), ..Default::default() },
    };
    let mut own = flags.nodes()?;
    for n in own.controller.iter_mut().chain(own.detector.iter_mut()) {
        n.run.ready.timeout_s = READY_S;
    }
    Ok(own)
}

/// The run's perception: a detector is judged on camera frames; a controller on what it reads.
fn perception(role: Role, args: &ConformNodeArgs) -> anyhow::Result<PerceptionSource> {
    match (role, args.perception) {
        (Role::Controller, p) => Ok(p.unwrap_or(PerceptionSource::GroundTruth)),
        (Role::Detector, None | Some(PerceptionSource::Camera)) => Ok(PerceptionSource::Camera),
        (Role::Detector, Some(_)) => anyhow::bail!(
            "a detector answers camera frames: `--perception ground-truth` gives it none (fix: drop --perception)"
        ),
    }
}

/// Subscribes the observer to everything the rules read.
async fn watch(lp: &LoopRun) -> anyhow::Result<(Arc<Mutex<Seen>>, Vec<CallbackSubscriber>)> {
    let seen = Arc::new(Mutex::new(Seen::default()));
    let bus = lp.bus();
    let s = seen.clone();
    let a = bus.subscribe_with(topics::VEHICLE_STATE, move |m| s.lock().states.push(m)).await?;
    let s = seen.clone();
    let b = bus.subscribe_with(topics::VEHICLE_CONTROL, move |m| s.lock().answers.push(m)).await?;
    let s = seen.clone();
    let c = bus.subscribe_with(topics::OBJECTS, move |m| s.lock().frames.push(m)).await?;
    let s = seen.clone();
    let d = bus.subscribe_with(topics::PERCEPTION_OBJECTS, move |m| s.lock().detections.push(m)).await?;
    let s = seen.clone();
    let e = bus.subscribe_with(topics::ACC_STATUS, move |_| s.lock().statuses += 1).await?;
    Ok((seen, vec![a, b, c, d, e]))
}

/// Waits for the simulator's end (bounded); its lockstep timeouts and how it ended.
async fn run_to_end(lp: &mut LoopRun, duration_s: f64) -> (u64, Option<String>) {
    let deadline = Instant::now() + Duration::from_secs_f64(duration_s * 20.0 + 60.0);
    while !lp.check().over() && Instant::now() < deadline {
        tokio::time::sleep(NODE_POLL).await;
    }
    tokio::time::sleep(crate::launch::SETTLE).await;
    match lp.sim_report() {
        Ok(r) => (r.lockstep_timeouts, r.end.map(|e| e.reason)),
        Err(_) => (0, Some("the simulator left no report".into())),
    }
}

fn verdict(rule: &'static str, ok: bool, detail: String) -> Verdict {
    Verdict { rule, outcome: if ok { Outcome::Pass } else { Outcome::Fail }, detail }
}

impl Role {
    /// The node's name on the bus.
    fn node(self) -> &'static str {
        match self {
            Role::Controller => "acc",
            Role::Detector => "detect",
        }
    }
}

/// The node became ready, its liveliness token seen before the first step, and `kept` it to
/// the end of the run.
fn token(role: Role, started: &Result<(), slipstream_launch::Error>, kept: bool) -> Verdict {
    let name = role.node();
    match started {
        Ok(()) if kept => {
            verdict("token", true, format!("nodes/{name} declared before the first step, kept to the end"))
        }
        Ok(()) => verdict(
            "token",
            false,
            format!("nodes/{name} was withdrawn during the run (keep it for as long as the node answers)"),
        ),
        Err(e) => verdict("token", false, e.chain()),
    }
}

/// The node under test ended before the run: its exit and its last words (a traceback's last
/// line, an error), where its log is.
fn died_verdict(end: &slipstream_launch::NodeEnd) -> Verdict {
    let code = end.exit_code.map_or("killed by a signal".to_string(), |c| format!("exit code {c}"));
    let said = end.why().map_or(String::new(), |w| format!(": {w}"));
    verdict(
        "kept_running",
        false,
        format!("{} ended before the run was over ({code}){said} (its log: {})", end.node, end.log.display()),
    )
}

/// Rules that judge the node's answers, when it gave none that decoded: failed, saying so,
/// never passed on zero evidence.
fn without_answers(rules: &[&'static str], output: &str, undecodable: u64) -> Vec<Verdict> {
    let detail = match undecodable {
        0 => format!("no answer on {output}: nothing to judge"),
        n => format!("no decodable answer on {output} ({n} payloads did not decode): nothing to judge"),
    };
    rules.iter().map(|rule| verdict(rule, false, detail.clone())).collect()
}

/// The controller's rules: one answer per state, naming its step, stamped with its stamp,
/// under the node's name, pedals in range, acc/status published.
fn judge_controller(seen: &Seen, timeouts: u64, ended: Option<&str>) -> Vec<Verdict> {
    let steps: BTreeMap<u64, u64> = seen.states.iter().map(|s| (s.msg.step, s.header.stamp_sim_ns)).collect();
    let mut answered: BTreeMap<u64, usize> = BTreeMap::new();
    let (mut wrong_step, mut wrong_stamp, mut strangers, mut out_of_range) = (None, None, None, None);
    for a in &seen.answers {
        let step = a.msg.answers_step.unwrap_or(u64::MAX);
        match steps.get(&step) {
            None => {
                let named = a.msg.answers_step.map_or("no step".into(), |s| format!("step {s}"));
                let _ = wrong_step.get_or_insert(format!("an answer names {named}, which no state had"));
            }
            Some(&stamp) if stamp != a.header.stamp_sim_ns => {
                let _ = wrong_stamp.get_or_insert(format!(
                    "the answer to step {step} is stamped {} ns; its state's stamp_sim_ns is {stamp} ns (copy it: the simulated time, not the wall clock)",
                    a.header.stamp_sim_ns
                ));
            }
            Some(_) => *answered.entry(step).or_default() += 1,
        }
        if a.source.as_deref() != Some("acc") {
            let _ = strangers.get_or_insert(format!("an answer attached {:?}, not \"acc\"", a.source));
        }
        let pedal = |p: f32| p.is_finite() && (0.0..=1.0).contains(&p);
        if !pedal(a.msg.throttle) || !pedal(a.msg.brake) {
            let _ = out_of_range.get_or_insert(format!("throttle {}, brake {}", a.msg.throttle, a.msg.brake));
        }
    }
    let all = steps.len();
    let once = steps.keys().filter(|k| answered.get(k) == Some(&1)).count();
    let ended = ended.unwrap_or("not at all");
    let every_step = verdict(
        "every_step_answered",
        once == all && all > 0 && timeouts == 0,
        format!("{once} of {all} steps answered once; {timeouts} lockstep timeouts; the run ended: {ended}"),
    );
    let status =
        verdict("status", seen.statuses > 0, format!("{} acc/status messages (what the judge reads)", seen.statuses));
    if seen.answers.is_empty() {
        let mut v = vec![every_step];
        v.extend(without_answers(
            &["answers_step", "stamp_copied", "attachment", "pedals"],
            "vehicle/control",
            seen.undecodable,
        ));
        v.push(status);
        return v;
    }
    vec![
        every_step,
        verdict(
            "answers_step",
            wrong_step.is_none(),
            wrong_step.unwrap_or_else(|| "every answer names a step answered".into()),
        ),
        verdict(
            "stamp_copied",
            wrong_stamp.is_none(),
            wrong_stamp.unwrap_or_else(|| "every answer carries its state's stamp".into()),
        ),
        verdict("attachment", strangers.is_none(), strangers.unwrap_or_else(|| "every answer attached \"acc\"".into())),
        verdict(
            "pedals",
            out_of_range.is_none(),
            out_of_range.unwrap_or_else(|| "throttle and brake within 0..1".into()),
        ),
        status,
    ]
}

/// The detector's rules: one answer per frame, stamped with it, in order, under its name.
fn judge_detector(seen: &Seen) -> Vec<Verdict> {
    let frames: std::collections::BTreeSet<u64> = seen.frames.iter().map(|f| f.header.stamp_sim_ns).collect();
    let mut per_frame: BTreeMap<u64, usize> = BTreeMap::new();
    let mut stray = None;
    for d in &seen.detections {
        match frames.contains(&d.header.stamp_sim_ns) {
            true => *per_frame.entry(d.header.stamp_sim_ns).or_default() += 1,
            false => {
                let _ = stray.get_or_insert(format!(
                    "detections stamped {} ns, the stamp of no frame (copy the frame's stamp_sim_ns)",
                    d.header.stamp_sim_ns
                ));
            }
        }
    }
    let once = frames.iter().filter(|f| per_frame.get(f) == Some(&1)).count();
    let mut by_stamp: Vec<&Received<Detections>> = seen.detections.iter().collect();
    by_stamp.sort_by_key(|d| d.header.stamp_sim_ns);
    let in_order = by_stamp.windows(2).all(|w| w[0].msg.frame_seq < w[1].msg.frame_seq);
    let strangers = seen.detections.iter().find(|d| d.source.as_deref() != Some("detect"));
    let every_frame = verdict(
        "every_frame_answered",
        once == frames.len() && !frames.is_empty(),
        format!("{once} of {} frames answered once", frames.len()),
    );
    if seen.detections.is_empty() {
        let mut v = vec![every_frame];
        v.extend(without_answers(&["stamp_copied", "frame_seq", "attachment"], "perception/objects", seen.undecodable));
        return v;
    }
    vec![
        every_frame,
        verdict(
            "stamp_copied",
            stray.is_none(),
            stray.unwrap_or_else(|| "every answer carries its frame's stamp".into()),
        ),
        verdict("frame_seq", in_order, format!("frame_seq rises with the frames: {in_order}")),
        verdict(
            "attachment",
            strangers.is_none(),
            strangers
                .map_or("every answer attached \"detect\"".into(), |d| format!("an answer attached {:?}", d.source)),
        ),
    ]
}
