//! `conform sim` on the bus: subscribes to every key of the contract, records what arrives
//! (decoded strictly, errors kept), asks for the camera info as a late subscriber, and either
//! probes the control path with a command of its own or, in lockstep, answers every step as
//! the controller the simulator waits for. Every wait is bounded.

use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use serde::de::DeserializeOwned;
use zenoh::sample::Sample;

use super::observed::{FrameSeen, KeyLog, LockstepLog, ObjectSeen, Observed, ProbeLog, StateSeen};
use super::ConformSimArgs;
use crate::bus::{Bus, BusError, Declared, Publisher};
use crate::msg::{self, CameraFrameRef, ControlCommand, Message, SimEventKind, SimMode, Stamped};
use crate::topics::{self, Topic};

/// The probe's command: a gentle brake, exact in f32 so the state can echo it bit for bit.
pub const PROBE: ControlCommand =
    ControlCommand { throttle: 0.0, brake: 0.3125, steer: 0.0, answers_step: None, perception_stamp_pub_ns: None };
/// How long the probe sends (50 Hz) before it gives up.
const PROBE_FOR: Duration = Duration::from_secs(1);

type Shared = Arc<Mutex<Observed>>;

/// Conform's clock and record, shared with Zenoh's callbacks.
#[derive(Clone)]
struct Tap {
    observed: Shared,
    start: Instant,
}

impl Tap {
    fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Decodes a payload as `M` into the key's log; the decoded message when it is valid.
    fn take<M: Message + DeserializeOwned>(&self, sample: &Sample, log: fn(&mut Observed) -> &mut KeyLog) -> Option<M> {
        let at = self.now_s();
        let bytes = sample.payload().to_bytes();
        let mut o = self.observed.lock();
        match msg::decode::<M>(&bytes) {
            Ok(Stamped { header, msg }) => {
                log(&mut o).push(header, at);
                Some(msg)
            }
            Err(e) => {
                log(&mut o).reject(e.to_string());
                None
            }
        }
    }
}

/// Lockstep: answers each step once, as the node the simulator waits for, at the pace of the
/// simulated clock. A lockstep simulator runs as fast as its slowest answer: answered at once,
/// a 40 s scenario would end within seconds of wall time, before the watch is over. Paced,
/// the watch sees the same stretch of simulated time in every clock mode.
struct Answerer {
    /// Steps to answer, to the pacing task (at most one is outstanding: the simulator waits).
    due: tokio::sync::mpsc::Sender<(u64, u64)>,
    physics_hz: Option<f64>,
    last: Option<u64>,
}

/// Steps queued for the pacing task at most (a lockstep simulator waits for each answer).
const ANSWERS_QUEUED: usize = 64;

impl Answerer {
    /// The answer to step `k`: a light throttle on even steps, coasting on odd ones (the ego
    /// slows gently), so a state showing the answer to an older step is told apart.
    fn command(k: u64) -> ControlCommand {
        let throttle = if k.is_multiple_of(2) { 0.125 } else { 0.0 };
        ControlCommand { throttle, brake: 0.0, steer: 0.0, answers_step: Some(k), perception_stamp_pub_ns: None }
    }

    /// Starts the pacing task: it publishes the answer to a step stamped `t` no sooner than
    /// `t - t_first` after the first answer.
    fn start(publisher: Publisher<ControlCommand>, tap: Tap) -> Answerer {
        let (due, mut steps) = tokio::sync::mpsc::channel::<(u64, u64)>(ANSWERS_QUEUED);
        tokio::spawn(async move {
            let mut origin: Option<(tokio::time::Instant, u64)> = None;
            while let Some((k, stamp_sim_ns)) = steps.recv().await {
                let (t0, s0) = *origin.get_or_insert((tokio::time::Instant::now(), stamp_sim_ns));
                tokio::time::sleep_until(t0 + Duration::from_nanos(stamp_sim_ns.saturating_sub(s0))).await;
                let cmd = Answerer::command(k);
                if let Err(e) = publisher.put(stamp_sim_ns, &cmd) {
                    tracing::warn!("conform: answer to step {k}: {e}");
                    continue;
                }
                if let Some(l) = tap.observed.lock().lockstep.as_mut() {
                    l.answered.insert(k, cmd);
                }
            }
        });
        Answerer { due, physics_hz: None, last: None }
    }

    fn answer(&mut self, k: u64, stamp_sim_ns: u64) {
        if self.last.is_some_and(|last| last >= k) {
            return;
        }
        if self.due.try_send((k, stamp_sim_ns)).is_ok() {
            self.last = Some(k);
        }
    }

    /// The step a speed message stamped `t_ns` belongs to, from sim/clock's physics rate.
    fn step_of(&self, t_ns: u64) -> Option<u64> {
        self.physics_hz.map(|hz| (t_ns as f64 * hz / 1e9).round() as u64)
    }
}

/// Watches the simulator as `args` says and returns what was seen.
pub async fn watch(bus: &Bus, args: &ConformSimArgs) -> Result<Observed, BusError> {
    let t = bus.topics();
    let key = |topic: Topic| t.key(topic).to_string();
    let observed = Observed {
        speed: KeyLog::new(key(Topic::VehicleSpeed)),
        state: KeyLog::new(key(Topic::VehicleState)),
        clock: KeyLog::new(key(Topic::SimClock)),
        camera: KeyLog::new(key(Topic::CameraFront)),
        camera_info: KeyLog::new(key(Topic::CameraFrontInfo)),
        objects: KeyLog::new(key(Topic::Objects)),
        road: KeyLog::new(key(Topic::SimRoad)),
        ego: KeyLog::new(key(Topic::SimEgo)),
        narrow: KeyLog::new(key(Topic::CameraNarrow)),
        events: KeyLog::new(key(Topic::SimEvents)),
        lockstep: args.lockstep.then(|| LockstepLog { name: bus.node().to_string(), ..LockstepLog::default() }),
        ..Observed::default()
    };
    let tap = Tap { observed: Arc::new(Mutex::new(observed)), start: Instant::now() };
    let answerer = match args.lockstep {
        true => Some(Arc::new(Mutex::new(Answerer::start(bus.publisher(topics::VEHICLE_CONTROL).await?, tap.clone())))),
        false => None,
    };
    let subs = subscribe(bus, &tap, answerer.clone()).await?;
    let first = wait_first(&tap, Duration::from_secs_f64(args.wait)).await;
    if first {
        observe(bus, &tap, Duration::from_secs_f64(args.duration)).await?;
        let lockstep_sim = tap.observed.lock().clocks.last().is_some_and(|c| c.mode == SimMode::Lockstep);
        if !args.lockstep && !args.no_control && !lockstep_sim {
            probe(bus, &tap).await?;
        }
    }
    drop(subs);
    drop(answerer);
    let mut o = tap.observed.lock().clone();
    o.window_s = tap.now_s();
    Ok(o)
}

/// Declares every subscription; vehicle/state last, so a lockstep simulator that waits for a
/// state subscriber starts once all of conform listens.
async fn subscribe(bus: &Bus, tap: &Tap, answerer: Option<Arc<Mutex<Answerer>>>) -> Result<Vec<Declared>, BusError> {
    let t = bus.topics();
    let mut subs = Vec::new();
    let mut on = async |topic: Topic, latched: bool, f: Box<dyn Fn(Sample) + Send + Sync>| -> Result<(), BusError> {
        subs.push(bus.subscribe_samples(t.key(topic), latched, f).await?);
        Ok(())
    };
    let tp = tap.clone();
    on(
        Topic::CameraFrontInfo,
        true,
        Box::new(move |s| {
            if let Some(info) = tp.take::<msg::CameraInfo>(&s, |o| &mut o.camera_info) {
                tp.observed.lock().info.get_or_insert(info);
            }
        }),
    )
    .await?;
    let tp = tap.clone();
    on(Topic::SimRoad, true, Box::new(move |s| drop(tp.take::<msg::RoadSpec>(&s, |o| &mut o.road)))).await?;
    let tp = tap.clone();
    on(
        Topic::SimEgo,
        true,
        Box::new(move |s| {
            tp.take::<msg::EgoInfo>(&s, |o| &mut o.ego);
        }),
    )
    .await?;
    let tp = tap.clone();
    on(
        Topic::SimEvents,
        false,
        Box::new(move |s| match tp.take::<msg::SimEvent>(&s, |o| &mut o.events).map(|e| e.kind) {
            Some(SimEventKind::ControlTimeout { late }) => tp.observed.lock().timeouts.push(late),
            Some(SimEventKind::ScenarioEnd { reason, .. }) => drop(tp.observed.lock().ended.get_or_insert(reason)),
            _ => {}
        }),
    )
    .await?;
    let tp = tap.clone();
    on(Topic::Objects, false, Box::new(move |s| take_objects(&tp, &s))).await?;
    let tp = tap.clone();
    on(Topic::CameraFront, false, Box::new(move |s| take_frame(&tp, &s, true))).await?;
    let tp = tap.clone();
    on(Topic::CameraNarrow, false, Box::new(move |s| take_frame(&tp, &s, false))).await?;
    let (tp, ans) = (tap.clone(), answerer.clone());
    on(
        Topic::SimClock,
        false,
        Box::new(move |s| {
            if let Some(clock) = tp.take::<msg::SimClock>(&s, |o| &mut o.clock) {
                tp.observed.lock().clocks.push(clock);
                if let Some(a) = &ans {
                    a.lock().physics_hz = Some(clock.physics_hz);
                }
            }
        }),
    )
    .await?;
    let (tp, ans) = (tap.clone(), answerer.clone());
    on(
        Topic::VehicleSpeed,
        false,
        Box::new(move |s| {
            let stamp = tp
                .take::<msg::Speed>(&s, |o| &mut o.speed)
                .and_then(|_| tp.observed.lock().speed.seen.last().map(|x| x.header.stamp_sim_ns));
            if let (Some(t), Some(a)) = (stamp, &ans) {
                let mut a = a.lock();
                if let Some(k) = a.step_of(t) {
                    a.answer(k, t);
                }
            }
        }),
    )
    .await?;
    let (tp, ans) = (tap.clone(), answerer);
    on(Topic::VehicleState, false, Box::new(move |s| take_state(&tp, &s, ans.as_deref()))).await?;
    Ok(subs)
}

fn take_state(tap: &Tap, sample: &Sample, answerer: Option<&Mutex<Answerer>>) {
    let Some(state) = tap.take::<msg::VehicleState>(sample, |o| &mut o.state) else { return };
    let stamp = {
        let mut o = tap.observed.lock();
        let seen = o.state.seen.last().copied();
        let Some(seen) = seen else { return };
        o.states.push(StateSeen {
            stamp_sim_ns: seen.header.stamp_sim_ns,
            step: state.step,
            applied: state.applied,
            command_stamp_pub_ns: state.control_timing.map(|t| t.command_stamp_pub_ns),
            arrived_s: seen.arrived_s,
        });
        seen.header.stamp_sim_ns
    };
    if let Some(a) = answerer {
        a.lock().answer(state.step, stamp);
    }
}

fn take_objects(tap: &Tap, sample: &Sample) {
    let Some(gt) = tap.take::<msg::GroundTruthObjects>(sample, |o| &mut o.objects) else { return };
    let mut o = tap.observed.lock();
    let Some(stamp_sim_ns) = o.objects.seen.last().map(|s| s.header.stamp_sim_ns) else { return };
    o.objects_seen.extend(gt.objects.iter().map(|g| ObjectSeen {
        stamp_sim_ns,
        id: g.id,
        position_in_ego_m: [g.position_in_ego_m[0], g.position_in_ego_m[1]],
        velocity_in_ego_mps: [g.velocity_in_ego_mps[0], g.velocity_in_ego_mps[1]],
    }));
}

fn take_frame(tap: &Tap, sample: &Sample, front: bool) {
    let at = tap.now_s();
    let bytes = sample.payload().to_bytes();
    let mut o = tap.observed.lock();
    let decoded = msg::decode::<CameraFrameRef>(&bytes);
    let log = if front { &mut o.camera } else { &mut o.narrow };
    match decoded {
        Ok(f) => {
            log.push(f.header, at);
            if front {
                o.frames.push(FrameSeen { width: f.msg.width, height: f.msg.height, encoding: f.msg.encoding });
            }
        }
        Err(e) => log.reject(e.to_string()),
    }
}

/// Waits until the first vehicle/speed (or anything undecodable on it) arrives.
async fn wait_first(tap: &Tap, wait: Duration) -> bool {
    let deadline = Instant::now() + wait;
    loop {
        let arrived = {
            let o = tap.observed.lock();
            !o.speed.seen.is_empty() || o.speed.bad > 0 || !o.state.seen.is_empty()
        };
        if arrived {
            return true;
        }
        if Instant::now() >= deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Watches for `duration`; half way, a second subscriber asks for the camera info.
async fn observe(bus: &Bus, tap: &Tap, duration: Duration) -> Result<(), BusError> {
    tokio::time::sleep(duration / 2).await;
    let asked = tap.now_s();
    tap.observed.lock().late_info_asked = true;
    let tp = tap.clone();
    let late = bus
        .subscribe_samples(bus.topics().key(Topic::CameraFrontInfo), true, move |s| {
            if msg::decode::<msg::CameraInfo>(&s.payload().to_bytes()).is_ok() {
                let mut o = tp.observed.lock();
                if o.late_info_after_s.is_none() {
                    o.late_info_after_s = Some(tp.now_s() - asked);
                }
            }
        })
        .await?;
    tokio::time::sleep(duration - duration / 2).await;
    let bound = Duration::from_secs_f64(super::rules::LATE_INFO_BOUND_S + 1.0);
    let until = Instant::now() + bound.saturating_sub(Duration::from_secs_f64(tap.now_s() - asked));
    while tap.observed.lock().late_info_after_s.is_none() && Instant::now() < until {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    drop(late);
    Ok(())
}

/// Sends [`PROBE`] at 50 Hz, stamped as the newest state, until a state shows it applied (and
/// 100 ms more) or [`PROBE_FOR`] passes.
async fn probe(bus: &Bus, tap: &Tap) -> Result<(), BusError> {
    let publisher = bus.publisher(topics::VEHICLE_CONTROL).await?;
    let started_s = tap.now_s();
    tap.observed.lock().probe = Some(ProbeLog { started_s, command: Some(PROBE), sent: 0 });
    let deadline = Instant::now() + PROBE_FOR;
    let mut seen_at: Option<Instant> = None;
    while Instant::now() < deadline && seen_at.is_none_or(|t| t.elapsed() < Duration::from_millis(100)) {
        let stamp = {
            let o = tap.observed.lock();
            if seen_at.is_none() && o.states.iter().any(|s| s.arrived_s >= started_s && s.applied.brake == PROBE.brake)
            {
                seen_at = Some(Instant::now());
            }
            o.states.last().map_or(0, |s| s.stamp_sim_ns)
        };
        publisher.put(stamp, &PROBE)?;
        if let Some(p) = tap.observed.lock().probe.as_mut() {
            p.sent += 1;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    Ok(())
}
