//! Re-simulation: a recorded run stands in for the simulator. Today's detector and ACC start
//! as in `up` (through [`LoopRun`], without the simulator), the recording's simulator-side
//! messages (camera, speed, state, ground truth, clock, events) and operator commands are played
//! to them byte for byte, and their new outputs are compared with the recorded ones.
//!
//! The replay goes step by step, as the simulator does in lockstep: all the inputs of one
//! simulated step, then a wait (at most [`OUTPUT_WAIT`]) for the outputs the recorded run had
//! for that step: the detections of the step's frame, the command answering its speed. So no
//! frame is skipped however slow the node, and with a lockstep recording the nodes see their
//! inputs in the recorded order: the same nodes give the same bytes.
//!
//! A recording made in realtime or fast mode may lack messages (its recorder counted them as
//! lost). The rule: a step is played with what the recording has of it; a recorded command
//! whose speed message the recording lacks answers nothing that is played, so it is not
//! waited for and is counted (`commands_without_input`), as are the recording's own sequence
//! gaps per input key (`lost_in_recording`). When today's nodes stop answering, the replay
//! ends, the nodes are stopped and the report is written all the same, naming the steps and
//! the recording's gaps.
//!
//! Outputs are paired by what they answer (detections by frame sequence number, commands by
//! the simulated time of the speed message) and compared on their bodies, byte for byte,
//! without the wall-clock fields: the header (its publish stamp) and a command's
//! `perception_stamp_pub_ns` (the publish stamp of the detections it used, new in a replay).

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use parking_lot::{Condvar, Mutex};
use serde::Serialize;

use slipstream_acc::PerceptionSource;
use slipstream_contract::bus::{Bus, Declared};
use slipstream_contract::config::ConnectArgs;
use slipstream_contract::msg::{
    self, AccStatus, ControlCommand, Detections, MessageKind, SimClock, SimEvent, SimEventKind, SimMode,
};
use slipstream_contract::topics::Topic;
use slipstream_launch::{ClockMode, LoopRun, LoopSpec, Network, NodeEnd, OwnNodes};
use slipstream_record::{each_message, each_message_until, is_viewable_copy, output_for, Output};

/// How long a step waits for the outputs the recording has for it.
pub(crate) const OUTPUT_WAIT: Duration = Duration::from_secs(5);
/// How often a wait for outputs looks whether the replay is to stop.
const STOP_POLL: Duration = Duration::from_millis(100);
/// Steps in a row whose outputs did not come before the replay gives up (the nodes stopped).
const GIVE_UP_AFTER: u32 = 3;

/// A message's role in a re-simulation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    /// Played to today's nodes (what the simulator and the operator published).
    Input,
    /// Compared with what today's nodes publish.
    Output,
}

fn role(kind: MessageKind) -> Role {
    match kind {
        MessageKind::Detections | MessageKind::ControlCommand | MessageKind::AccStatus => Role::Output,
        _ => Role::Input,
    }
}

/// A payload and what of it is compared: its body without the wall-clock fields.
#[derive(Debug, Clone)]
struct Payload {
    bytes: Vec<u8>,
    compared: Vec<u8>,
}

/// The outputs worth comparing, keyed by what they answer: detections by frame sequence
/// number, commands by the simulated time of the speed message they answer. The first of
/// each key is kept.
#[derive(Debug, Default)]
struct Outputs {
    detections: BTreeMap<u64, Payload>,
    commands: BTreeMap<u64, Payload>,
    /// Commands that answer no step (the ACC's watchdog).
    unpaired_commands: u64,
}

impl Outputs {
    /// Takes `bytes` if it is an output worth comparing.
    fn take(&mut self, bytes: Vec<u8>) {
        let Ok(kind) = msg::peek_kind(&bytes) else { return };
        let Ok((header, body_at)) = msg::decode_header(&bytes, kind) else { return };
        match kind {
            MessageKind::Detections => {
                // The body whole: frame_stamp_pub_ns is the replayed frame's own stamp.
                if let Ok(d) = msg::decode::<Detections>(&bytes) {
                    let compared = bytes[body_at..].to_vec();
                    self.detections.entry(d.msg.frame_seq).or_insert(Payload { bytes, compared });
                }
            }
            MessageKind::ControlCommand => match msg::decode::<ControlCommand>(&bytes) {
                Ok(c) if c.msg.answers_step.is_some() => {
                    // perception_stamp_pub_ns is the wall-clock stamp of the perception used:
                    // new detections, new stamp. The rest is compared as encoded.
                    let command = ControlCommand { perception_stamp_pub_ns: None, ..c.msg };
                    let Ok(compared) = postcard::to_stdvec(&command) else { return };
                    self.commands.entry(header.stamp_sim_ns).or_insert(Payload { bytes, compared });
                }
                Ok(_) => self.unpaired_commands += 1,
                Err(_) => {}
            },
            _ => {}
        }
    }
}

/// What the recording holds (a first pass over it).
#[derive(Debug, Default)]
struct Recorded {
    scenario: Option<String>,
    clock: Option<SimMode>,
    set_speed_mps: Option<f64>,
    outputs: Outputs,
    inputs: u64,
    /// The keys (relative to the recording's namespace) that hold at least one message.
    keys: std::collections::BTreeSet<String>,
    /// Sequence gaps of the simulator's messages, per key: lost before they were recorded.
    lost: Gaps,
}

/// Sequence gaps per key and publisher, as the recording holds them.
#[derive(Debug, Default)]
struct Gaps {
    last: BTreeMap<(String, Option<String>), u64>,
    per_key: BTreeMap<String, u64>,
}

impl Gaps {
    fn see(&mut self, key: &str, publisher: Option<&String>, seq: u64) {
        let last = self.last.entry((key.to_string(), publisher.cloned())).or_insert(seq);
        if seq > *last + 1 {
            *self.per_key.entry(key.to_string()).or_default() += seq - *last - 1;
        }
        *last = (*last).max(seq);
    }
}

impl Recorded {
    fn scan(path: &Path) -> Result<Recorded> {
        let mut rec = Recorded::default();
        each_message(path, |m| {
            if is_viewable_copy(&m.channel) {
                return Ok(());
            }
            let ns = m.channel.metadata.get("namespace").map_or("", String::as_str);
            let key = m.channel.topic.strip_prefix(ns).unwrap_or(&m.channel.topic).trim_start_matches('/');
            if !rec.keys.contains(key) {
                rec.keys.insert(key.to_string());
            }
            let bytes = m.data.into_owned();
            let Ok(kind) = msg::peek_kind(&bytes) else { return Ok(()) };
            if role(kind) == Role::Input {
                if let Ok((h, _)) = msg::decode_header(&bytes, kind) {
                    rec.lost.see(key, m.channel.metadata.get("publisher"), h.seq);
                }
            }
            match kind {
                MessageKind::SimEvent => {
                    if let Ok(e) = msg::decode::<SimEvent>(&bytes) {
                        if let SimEventKind::ScenarioStart { name, .. } = e.msg.kind {
                            rec.scenario.get_or_insert(name);
                        }
                    }
                }
                MessageKind::SimClock => {
                    if let Ok(c) = msg::decode::<SimClock>(&bytes) {
                        rec.clock.get_or_insert(c.msg.mode);
                    }
                }
                MessageKind::AccStatus => {
                    if let Ok(s) = msg::decode::<AccStatus>(&bytes) {
                        rec.set_speed_mps.get_or_insert(s.msg.set_speed_mps);
                    }
                }
                _ => {}
            }
            match role(kind) {
                Role::Output => rec.outputs.take(bytes),
                Role::Input => rec.inputs += 1,
            }
            Ok(())
        })?;
        if rec.inputs == 0 {
            let problem = "holds no simulator messages to replay".to_string();
            return Err(Error::Recording { path: path.to_path_buf(), problem });
        }
        Ok(rec)
    }

    /// The latched inputs today's nodes cannot do without and the file lacks: a camera's
    /// calibration wherever its frames are replayed into the detector (it uses no frame
    /// without one). Keys are the default topic map's.
    fn missing(&self) -> Vec<&'static str> {
        if self.perception() != PerceptionSource::Camera {
            return Vec::new();
        }
        let keys = slipstream_contract::TopicMap::default();
        [(Topic::CameraFront, Topic::CameraFrontInfo), (Topic::CameraNarrow, Topic::CameraNarrowInfo)]
            .into_iter()
            .filter(|(frames, info)| {
                self.keys.contains(keys.key(*frames).as_str()) && !self.keys.contains(keys.key(*info).as_str())
            })
            .map(|(_, info)| info.name())
            .collect()
    }

    /// Refuses a file that cannot be re-simulated as it was run, saying what it lacks; warns
    /// about the road, without which the ACC runs with no lanes (an external simulator may
    /// publish none).
    fn check(&self, path: &Path) -> Result<()> {
        let missing = self.missing();
        if !missing.is_empty() {
            let problem = format!(
                "cannot be re-simulated: it has no {}, and the detector uses no frame without its camera's calibration (fix: record the run again with its latched topics: `up --record`, or `slipstream record` with no keys or with these ones named)",
                missing.join(" and ")
            );
            return Err(Error::Recording { path: path.to_path_buf(), problem });
        }
        let road = slipstream_contract::TopicMap::default().key(Topic::SimRoad);
        if !self.keys.contains(road.as_str()) {
            tracing::warn!("{} has no sim/road: the ACC replays without the road's lanes", path.display());
        }
        Ok(())
    }

    fn clock(&self) -> ClockMode {
        match self.clock {
            Some(SimMode::Lockstep) => ClockMode::Lockstep,
            Some(SimMode::Fast) => ClockMode::Fast,
            _ => ClockMode::Realtime,
        }
    }

    /// Camera perception when the recorded run had a detector.
    fn perception(&self) -> PerceptionSource {
        if self.outputs.detections.is_empty() {
            PerceptionSource::GroundTruth
        } else {
            PerceptionSource::Camera
        }
    }
}

/// Today's outputs as they arrive, with a condition to wait on.
#[derive(Default)]
struct Inbox {
    outputs: Mutex<Outputs>,
    arrived: Condvar,
}

impl Inbox {
    async fn start(bus: &Bus) -> Result<(Arc<Inbox>, Vec<Declared>)> {
        let inbox = Arc::new(Inbox::default());
        let mut subs = Vec::new();
        for topic in [Topic::PerceptionObjects, Topic::VehicleControl] {
            let i = inbox.clone();
            let sub = bus
                .subscribe_samples(bus.topics().key(topic), false, move |sample| {
                    i.outputs.lock().take(sample.payload().to_bytes().into_owned());
                    i.arrived.notify_all();
                })
                .await?;
            subs.push(sub);
        }
        Ok((inbox, subs))
    }

    /// Waits until every frame in `frames` has its detections and `command` (a step's
    /// stamp) its command; false after `timeout` or once `stop` is set (looked at every
    /// [`STOP_POLL`]).
    fn wait(&self, frames: &[u64], command: Option<u64>, timeout: Duration, stop: &AtomicBool) -> bool {
        let deadline = Instant::now() + timeout;
        let mut o = self.outputs.lock();
        loop {
            let done = frames.iter().all(|f| o.detections.contains_key(f))
                && command.is_none_or(|c| o.commands.contains_key(&c));
            if done {
                return true;
            }
            let now = Instant::now();
            if now >= deadline || stop.load(Ordering::Relaxed) {
                return false;
            }
            self.arrived.wait_until(&mut o, deadline.min(now + STOP_POLL));
        }
    }
}

/// One simulated step being played: its stamp and the frames published in it.
#[derive(Default)]
struct Step {
    stamp_sim_ns: Option<u64>,
    frames: Vec<u64>,
    /// The step's speed message was played (a command answers it).
    speed: bool,
}

/// How the replay went.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ReplayStats {
    pub messages: u64,
    pub steps: u64,
    /// Steps whose recorded outputs did not all come within OUTPUT_WAIT.
    pub steps_timed_out: u64,
    /// Inputs that came in the file after a later step's (beyond the reorder window) and
    /// were played late.
    pub late_inputs: u64,
    /// Recorded commands answering a speed message the recording lacks (lost while
    /// recording): nothing played asks for them, so they are not waited for.
    pub commands_without_input: u64,
    /// Sequence gaps of the simulator's messages in the recording, per key (relative to the
    /// recording's namespace): what its recorder reported as lost.
    pub lost_in_recording: BTreeMap<String, u64>,
    /// Why the replay ended before the recording's end, when today's nodes stopped answering.
    pub gave_up: Option<String>,
    pub wall_s: f64,
    /// Stopped before the end of the recording (a signal).
    pub interrupted: bool,
}

/// Inputs read ahead and played in simulated-time order: the recorder receives each key on
/// its own path, so a step's state may sit in the file after the next step's speed.
const REORDER_WINDOW: usize = 512;

/// An input waiting in the reorder window.
struct Pending {
    channel: Arc<mcap::Channel<'static>>,
    kind: MessageKind,
    seq: u64,
    bytes: Vec<u8>,
}

/// The replay's state: the step being played, the publishers, the outputs to wait for.
struct Replayer<'a> {
    bus: &'a Bus,
    recorded: &'a Outputs,
    inbox: &'a Inbox,
    outputs: BTreeMap<u16, Option<Output>>,
    step: Step,
    /// Set when the replay is to end early.
    stop: &'a AtomicBool,
    in_a_row: u32,
    stats: ReplayStats,
    last_progress: Instant,
}

impl Replayer<'_> {
    /// Plays one input: a later step first finishes the one before (waits for its outputs).
    fn play(&mut self, stamp_sim_ns: u64, p: Pending, progress: &mut dyn FnMut(f64)) -> Result<()> {
        match self.step.stamp_sim_ns {
            Some(s) if stamp_sim_ns < s => self.stats.late_inputs += 1,
            Some(s) if stamp_sim_ns == s => {}
            _ => {
                self.finish_step()?;
                self.step = Step { stamp_sim_ns: Some(stamp_sim_ns), ..Step::default() };
                if self.last_progress.elapsed() >= Duration::from_secs(1) {
                    progress(stamp_sim_ns as f64 / 1e9);
                    self.last_progress = Instant::now();
                }
            }
        }
        match p.kind {
            MessageKind::CameraFrame => self.step.frames.push(p.seq),
            MessageKind::Speed => self.step.speed = true,
            _ => {}
        }
        let output = match self.outputs.get(&p.channel.id) {
            Some(o) => o,
            None => {
                let o = output_for(self.bus, &p.channel, &[], true)?;
                self.outputs.entry(p.channel.id).or_insert(o)
            }
        };
        if let Some(o) = output {
            o.put(p.bytes)?;
            self.stats.messages += 1;
        }
        Ok(())
    }

    /// Waits for the outputs the recording has for the step being played.
    fn finish_step(&mut self) -> Result<()> {
        let Some(stamp) = self.step.stamp_sim_ns else { return Ok(()) };
        let recorded = self.recorded;
        let frames: Vec<u64> =
            self.step.frames.iter().copied().filter(|f| recorded.detections.contains_key(f)).collect();
        let recorded_command = recorded.commands.contains_key(&stamp);
        if recorded_command && !self.step.speed {
            self.stats.commands_without_input += 1;
        }
        let command = (recorded_command && self.step.speed).then_some(stamp);
        self.stats.steps += 1;
        if self.inbox.wait(&frames, command, OUTPUT_WAIT, self.stop) {
            self.in_a_row = 0;
            return Ok(());
        }
        if self.stop.load(Ordering::Relaxed) {
            return Err(Error::Interrupted);
        }
        self.stats.steps_timed_out += 1;
        self.in_a_row += 1;
        if self.in_a_row >= GIVE_UP_AFTER {
            self.stats.gave_up = Some(format!(
                "today's nodes stopped answering: {} steps in a row without their outputs (at {:.2} s simulated); see their logs",
                self.in_a_row,
                stamp as f64 / 1e9
            ));
            return Err(Error::Interrupted);
        }
        Ok(())
    }
}

/// Plays the recording's inputs step by step, in simulated-time order, waiting after each
/// step for the outputs the recording has for it.
fn replay(
    bus: &Bus,
    path: &Path,
    recorded: &Outputs,
    inbox: &Inbox,
    progress: &mut dyn FnMut(f64),
    stop: &AtomicBool,
) -> Result<ReplayStats> {
    let started = Instant::now();
    let mut r = Replayer {
        bus,
        recorded,
        inbox,
        outputs: BTreeMap::new(),
        step: Step::default(),
        stop,
        in_a_row: 0,
        stats: ReplayStats::default(),
        last_progress: Instant::now(),
    };
    // Keyed by (simulated time, place in the file): time order, the file's order within a step.
    let mut window: BTreeMap<(u64, u64), Pending> = BTreeMap::new();
    let mut index = 0u64;
    // The reader stops at the first error of today's side, kept here: the reader's own
    // errors are the recording's.
    let mut failed: Option<Error> = None;
    let read = each_message_until(path, |m| {
        let stop_with = |e: Error, failed: &mut Option<Error>| {
            *failed = Some(e);
            Ok(ControlFlow::Break(()))
        };
        if stop.load(Ordering::Relaxed) {
            return stop_with(Error::Interrupted, &mut failed);
        }
        let (channel, bytes) = (m.channel, m.data.into_owned());
        let Ok(kind) = msg::peek_kind(&bytes) else { return Ok(ControlFlow::Continue(())) };
        if role(kind) == Role::Output {
            return Ok(ControlFlow::Continue(()));
        }
        let Ok((header, _)) = msg::decode_header(&bytes, kind) else { return Ok(ControlFlow::Continue(())) };
        window.insert((header.stamp_sim_ns, index), Pending { channel, kind, seq: header.seq, bytes });
        index += 1;
        if window.len() > REORDER_WINDOW {
            if let Some(((stamp, _), p)) = window.pop_first() {
                if let Err(e) = r.play(stamp, p, progress) {
                    return stop_with(e, &mut failed);
                }
            }
        }
        Ok(ControlFlow::Continue(()))
    });
    let rest = match failed {
        Some(e) => Err(e),
        None => read.map_err(Error::from).and_then(|_| {
            while let Some(((stamp, _), p)) = window.pop_first() {
                r.play(stamp, p, progress)?;
            }
            r.finish_step()
        }),
    };
    match rest {
        Err(Error::Interrupted) if r.stats.gave_up.is_some() => {}
        Err(Error::Interrupted) => r.stats.interrupted = true,
        other => other?,
    }
    r.stats.wall_s = started.elapsed().as_secs_f64();
    Ok(r.stats)
}

/// Recorded against replayed outputs of one kind.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Comparison {
    pub recorded: u64,
    pub replayed: u64,
    /// Paired and byte-identical bodies.
    pub identical: u64,
    /// Paired with different bodies.
    pub differing: u64,
    /// Recorded, not produced by today's nodes.
    pub missing: u64,
    /// Produced by today's nodes, not in the recording.
    pub extra: u64,
    /// For commands: the largest throttle or brake difference among the paired ones.
    pub max_abs_difference: Option<f64>,
    pub first_difference: Option<Difference>,
}

impl Comparison {
    pub fn same(&self) -> bool {
        self.differing == 0 && self.missing == 0 && self.extra == 0
    }
}

/// The first output that differs: what it answers, and both versions, readable.
#[derive(Debug, Clone, Serialize)]
pub struct Difference {
    pub answers: String,
    pub recorded: String,
    pub replayed: String,
}

fn compare(
    recorded: &BTreeMap<u64, Payload>,
    replayed: &BTreeMap<u64, Payload>,
    describe: fn(&Payload) -> String,
    answers: fn(u64) -> String,
    difference: Option<fn(&Payload, &Payload) -> Option<f64>>,
) -> Comparison {
    let mut c = Comparison { recorded: recorded.len() as u64, replayed: replayed.len() as u64, ..Default::default() };
    for (key, r) in recorded {
        let Some(n) = replayed.get(key) else {
            c.missing += 1;
            continue;
        };
        if let Some(d) = difference.and_then(|f| f(r, n)) {
            c.max_abs_difference = Some(c.max_abs_difference.map_or(d, |m| m.max(d)));
        }
        if r.compared == n.compared {
            c.identical += 1;
            continue;
        }
        c.differing += 1;
        c.first_difference.get_or_insert_with(|| Difference {
            answers: answers(*key),
            recorded: describe(r),
            replayed: describe(n),
        });
    }
    c.extra = replayed.keys().filter(|k| !recorded.contains_key(k)).count() as u64;
    c
}

fn describe_detections(p: &Payload) -> String {
    match msg::decode::<Detections>(&p.bytes) {
        Ok(d) if d.msg.detections.is_empty() => "no vehicles".into(),
        Ok(d) => d
            .msg
            .detections
            .iter()
            .map(|v| format!("#{} {:?} {:.2} m (conf {:.2})", v.track_id, v.class, v.distance_m, v.confidence))
            .collect::<Vec<_>>()
            .join(", "),
        Err(e) => format!("undecodable: {e}"),
    }
}

fn describe_command(p: &Payload) -> String {
    match msg::decode::<ControlCommand>(&p.bytes) {
        Ok(c) => format!("throttle {:.4} brake {:.4} steer {:.4}", c.msg.throttle, c.msg.brake, c.msg.steer),
        Err(e) => format!("undecodable: {e}"),
    }
}

fn command_difference(a: &Payload, b: &Payload) -> Option<f64> {
    let (a, b) = (msg::decode::<ControlCommand>(&a.bytes).ok()?, msg::decode::<ControlCommand>(&b.bytes).ok()?);
    Some(((a.msg.throttle - b.msg.throttle).abs().max((a.msg.brake - b.msg.brake).abs())) as f64)
}

/// What a re-simulation found.
#[derive(Debug, Clone, Serialize)]
pub struct ResimReport {
    pub recording: PathBuf,
    pub scenario: Option<String>,
    pub clock: ClockMode,
    pub perception: PerceptionSource,
    pub replay: ReplayStats,
    pub detections: Comparison,
    pub commands: Comparison,
    pub nodes: Vec<NodeEnd>,
    /// The nodes of the user's own that answered (`--controller`, `--detector`, `--loop`).
    pub own: OwnNodes,
    pub report_dir: PathBuf,
    /// What stopped the replay before the recording's end (a signal's name), if anything.
    pub stopped_by: Option<String>,
}

impl ResimReport {
    /// Everything recorded was answered and no node died (differences are findings, not
    /// failures).
    pub fn complete(&self) -> bool {
        self.replay.steps_timed_out == 0 && self.replay.gave_up.is_none() && !self.nodes.iter().any(|n| n.died)
    }
}

/// Replays `path` into today's detector and ACC, or `own` nodes in their place (started with
/// `connect`'s flags, logs in `dir`) and compares their outputs with the recorded ones.
/// `stop`, once set (a signal), ends the replay early: the nodes are stopped and the report
/// covers what was replayed (`replay.interrupted`).
pub async fn run(
    path: &Path,
    connect: &ConnectArgs,
    dir: &Path,
    own: OwnNodes,
    progress: &mut dyn FnMut(f64),
    stop: &AtomicBool,
) -> Result<ResimReport> {
    let mut recorded = tokio::task::block_in_place(|| Recorded::scan(path))?;
    recorded.check(path)?;
    // The scenario's own time gap and vehicle, as `up` gave them; otherwise today's ACC
    // settings decide (a changed settings file is what a re-simulation compares).
    let scenario = recorded.scenario.as_deref().and_then(|name| slipstream_sim::Scenario::find(name).ok());
    let spec = LoopSpec {
        scenario: recorded.scenario.clone().unwrap_or_else(|| "replay".into()),
        duration_s: 0.0,
        clock: recorded.clock(),
        perception: recorded.perception(),
        set_speed_mps: recorded.set_speed_mps.ok_or_else(|| {
            let problem = "has no acc/status: the ACC's set speed is unknown (record every key)".to_string();
            Error::Recording { path: path.to_path_buf(), problem }
        })?,
        time_gap_s: scenario.as_ref().and_then(|s| s.ego().time_gap_s),
        vehicle: scenario.as_ref().map(LoopSpec::vehicle_of),
        faults: None,
        link: Default::default(),
        own,
        egos: Vec::new(),
    };
    let mut lp =
        LoopRun::open(spec.clone(), Network::User { connect, sim_elsewhere: false }, &dir.join("logs"), "resim")
            .await?;
    let (inbox, subs) = Inbox::start(lp.bus()).await?;
    lp.start_controllers().await?;
    let replayed = tokio::task::block_in_place(|| replay(lp.bus(), path, &recorded.outputs, &inbox, progress, stop));
    tokio::time::sleep(slipstream_launch::SETTLE).await;
    for node in lp.check().died {
        tracing::warn!("{node} ended during the replay; see {}", lp.log(&node).display());
    }
    let nodes = lp.stop().await;
    drop(subs);
    lp.close().await;
    let mut replay = replayed?;
    replay.lost_in_recording = std::mem::take(&mut recorded.lost.per_key);
    let today = std::mem::take(&mut *inbox.outputs.lock());
    let o = &recorded.outputs;
    Ok(ResimReport {
        recording: path.to_path_buf(),
        scenario: recorded.scenario.clone(),
        clock: spec.clock,
        perception: spec.perception,
        replay,
        detections: compare(&o.detections, &today.detections, describe_detections, |seq| format!("frame #{seq}"), None),
        commands: compare(
            &o.commands,
            &today.commands,
            describe_command,
            |ns| format!("the speed at {:.3} s", ns as f64 / 1e9),
            Some(command_difference),
        ),
        nodes,
        own: spec.own.clone(),
        report_dir: dir.to_path_buf(),
        stopped_by: None,
    })
}

/// The summary printed at the end.
pub fn summary(r: &ResimReport) -> String {
    let mut s = format!(
        "\nreplayed {} ({}, {} clock, {} perception): {} messages in {} steps, {:.1} s\n",
        r.recording.display(),
        r.scenario.as_deref().unwrap_or("unknown scenario"),
        r.clock.name(),
        r.perception.name(),
        r.replay.messages,
        r.replay.steps,
        r.replay.wall_s
    );
    for (name, c) in [("detections", &r.detections), ("commands", &r.commands)] {
        if c.recorded == 0 && c.replayed == 0 {
            continue;
        }
        s.push_str(&format!(
            "  {name:<11} recorded {:>6}  replayed {:>6}  identical {:>6}  differing {:>6}  missing {:>4}  extra {:>4}{}\n",
            c.recorded,
            c.replayed,
            c.identical,
            c.differing,
            c.missing,
            c.extra,
            c.max_abs_difference.map_or(String::new(), |d| format!("  max |diff| {d:.4}"))
        ));
        if let Some(d) = &c.first_difference {
            s.push_str(&format!(
                "    first difference, {}:\n      recorded {}\n      today    {}\n",
                d.answers, d.recorded, d.replayed
            ));
        }
    }
    if r.replay.steps_timed_out > 0 {
        s.push_str(&format!(
            "  {} steps waited {:?} in vain for today's outputs\n",
            r.replay.steps_timed_out, OUTPUT_WAIT
        ));
    }
    let lost: u64 = r.replay.lost_in_recording.values().sum();
    if lost > 0 || r.replay.commands_without_input > 0 {
        let keys: Vec<String> = r.replay.lost_in_recording.iter().map(|(k, n)| format!("{k} {n}")).collect();
        s.push_str(&format!(
            "  the recording lacks {lost} of the simulator's messages ({}); {} recorded commands answer a speed it lacks: not waited for\n",
            if keys.is_empty() { "-".to_string() } else { keys.join(", ") },
            r.replay.commands_without_input
        ));
    }
    if let Some(why) = &r.replay.gave_up {
        s.push_str(&format!("  the replay ended early: {why}\n"));
    }
    let stopped;
    let verdict = match (r.detections.same() && r.commands.same(), r.complete(), &r.stopped_by) {
        (_, _, Some(signal)) if r.replay.interrupted => {
            stopped = format!("stopped by {signal} before the recording's end: compared up to there");
            stopped.as_str()
        }
        (true, true, _) => "today's nodes answer exactly as recorded",
        (false, true, _) => "today's nodes answer differently (above)",
        (_, false, _) => "the replay is incomplete (a node died or did not answer)",
    };
    s.push_str(&format!("  {verdict}\n  report: {}", r.report_dir.join("report.json").display()));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::{Header, Message};

    fn payload<M: Message>(stamp_sim_ns: u64, msg: &M) -> Vec<u8> {
        msg::encode(&Header { seq: 1, stamp_sim_ns, stamp_pub_ns: 1_700_000_000_000_000_000 + stamp_sim_ns }, msg)
    }

    fn command(throttle: f32, perception_stamp_pub_ns: Option<u64>, answers_step: Option<u64>) -> ControlCommand {
        ControlCommand { throttle, brake: 0.0, steer: 0.0, answers_step, perception_stamp_pub_ns }
    }

    fn detections(frame_seq: u64, distance_m: f64) -> Detections {
        let mut d = msg::example_detections();
        d.frame_seq = frame_seq;
        d.detections[0].distance_m = distance_m;
        d
    }

    #[test]
    fn outputs_pair_by_what_they_answer_and_leave_out_wall_clock_stamps() {
        let (mut recorded, mut today) = (Outputs::default(), Outputs::default());
        recorded.take(payload(10, &command(0.5, Some(111), Some(1))));
        recorded.take(payload(20, &command(0.5, Some(222), Some(2))));
        recorded.take(payload(30, &command(0.5, None, Some(3))));
        recorded.take(payload(35, &command(0.0, None, None)));
        // Other publish stamps, other perception stamps: the same answers.
        today.take(payload(10, &command(0.5, Some(999), Some(1))));
        // A different throttle for the second step, nothing for the third, one step more.
        today.take(payload(20, &command(0.25, Some(222), Some(2))));
        today.take(payload(40, &command(0.5, None, Some(4))));
        assert_eq!(recorded.unpaired_commands, 1, "the watchdog's command answers no step");
        let c = compare(
            &recorded.commands,
            &today.commands,
            describe_command,
            |ns| format!("{ns}"),
            Some(command_difference),
        );
        assert_eq!((c.recorded, c.replayed, c.identical, c.differing, c.missing, c.extra), (3, 3, 1, 1, 1, 1));
        assert_eq!(c.max_abs_difference, Some(0.25));
        assert!(!c.same());
        let first = c.first_difference.unwrap();
        assert_eq!(first.answers, "20");
        assert!(first.recorded.contains("throttle 0.5000") && first.replayed.contains("throttle 0.2500"), "{first:?}");
    }

    #[test]
    fn detections_compare_on_their_whole_body() {
        let (mut recorded, mut today) = (Outputs::default(), Outputs::default());
        for seq in 1..=3 {
            recorded.take(payload(seq * 50, &detections(seq, 27.5)));
            today.take(payload(seq * 50 + 7, &detections(seq, if seq == 3 { 27.75 } else { 27.5 })));
        }
        // Not an output: ignored.
        today.take(payload(5, &msg::Speed { speed_mps: 3.0 }));
        let c = compare(&recorded.detections, &today.detections, describe_detections, |s| format!("frame #{s}"), None);
        assert_eq!((c.identical, c.differing, c.missing, c.extra), (2, 1, 0, 0));
        let first = c.first_difference.unwrap();
        assert_eq!(first.answers, "frame #3");
        assert!(first.recorded.contains("27.50 m") && first.replayed.contains("27.75 m"), "{first:?}");
        let same = compare(&recorded.detections, &recorded.detections, describe_detections, |s| format!("{s}"), None);
        assert!(same.same() && same.identical == 3);
    }

    #[test]
    fn every_simulator_message_is_replayed_and_only_the_nodes_outputs_are_compared() {
        let outputs = [MessageKind::Detections, MessageKind::ControlCommand, MessageKind::AccStatus];
        for kind in outputs {
            assert_eq!(role(kind), Role::Output, "{kind:?}");
        }
        for (kind, _) in msg::examples() {
            assert_eq!(role(kind) == Role::Output, outputs.contains(&kind), "{kind:?}");
        }
    }
}
