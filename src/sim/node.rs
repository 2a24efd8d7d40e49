//! The simulator on the bus: publishes the world's topics at their rates, takes the ego's
//! commands from vehicle/control, and paces the steps (realtime, fast or lockstep).
//!
//! Each step k publishes what is due at simulation time t_k (speed, state, clock, camera frame
//! with its ground truth), then decides the ego's input for the step to k + 1:
//! - realtime / fast: the latest command received, held for `control.hold_ms` of simulated
//!   time, then a brake (the policy logs when it engages and when control resumes);
//! - lockstep, at every step that published speed or state: wait until every node in
//!   `lockstep.wait_for` answered step k (`answers_step == k`, the node named by the sample's
//!   attachment), or the step timeout passes (then warn, publish ControlTimeout naming the late
//!   nodes, and continue with the policy or stop).

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;

use super::ground_truth::ground_truth;
use super::render::{ObjectVisibility, Renderer};
use super::settings::{BeforeFirst, ControlPolicy, Mode, OnTimeout, SimSettings};
use super::world::{End, World, EGO_ID};
use crate::bus::{Bus, BusError, Received};
use crate::msg::{ControlCommand, ControlTiming, ImageEncoding, SimClock, SimEvent, SimEventKind, Speed, VehicleState};
use crate::topics;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("lockstep: {0}")]
    Lockstep(String),
    #[error("camera: {0}")]
    Camera(String),
}

/// How a run went.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SimReport {
    pub scenario: String,
    pub seed: u64,
    pub steps: u64,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    /// Simulated seconds per wall-clock second over the whole run.
    pub real_time_factor: f64,
    pub frames: u64,
    pub ego_collisions: u64,
    pub traffic_collisions: u64,
    /// Lockstep steps that timed out waiting for a controller.
    pub lockstep_timeouts: u64,
    /// Times the control policy had to brake for lack of commands.
    pub control_timeouts: u64,
    /// vehicle/control payloads that failed to decode (counted and logged, never applied).
    pub control_rejected: u64,
    /// Commands older than control.max_age_ms of simulated time when they came (not applied).
    pub control_stale: u64,
    /// None when stopped before the scenario ended.
    pub end: Option<End>,
}

impl SimReport {
    /// One paragraph for people.
    pub fn summary(&self) -> String {
        let outcome = match &self.end {
            Some(e) => format!("{} ({})", if e.success { "success" } else { "failure" }, e.reason),
            None => "stopped before the end".to_string(),
        };
        format!(
            "{} (seed {}): {outcome}\n  {:.1} s simulated in {:.1} s (real-time factor {:.1}), {} steps, {} frames\n  collisions: {} ego, {} traffic; lockstep timeouts {}, control timeouts {}, bad control messages {}, stale commands {}",
            self.scenario,
            self.seed,
            self.sim_time_s,
            self.wall_time_s,
            self.real_time_factor,
            self.steps,
            self.frames,
            self.ego_collisions,
            self.traffic_collisions,
            self.lockstep_timeouts,
            self.control_timeouts,
            self.control_rejected,
            self.control_stale
        )
    }
}

/// Whether a publisher with `rate_hz` is due at step `k` of a `physics_hz` clock: at step 0 and
/// whenever floor(t * rate) moves on.
pub fn due(k: u64, rate_hz: f64, physics_hz: u32) -> bool {
    let tick = |k: u64| ((k as f64 * rate_hz) / physics_hz as f64 + 1e-9).floor();
    k == 0 || tick(k) > tick(k - 1)
}

/// Commands as they arrive, handed from Zenoh's thread to the loop.
#[derive(Default)]
struct ControlInbox {
    queue: Mutex<VecDeque<Received<ControlCommand>>>,
    notify: tokio::sync::Notify,
}

impl ControlInbox {
    const CAPACITY: usize = 1024;

    fn push(&self, r: Received<ControlCommand>) {
        let mut q = self.queue.lock();
        if q.len() >= Self::CAPACITY {
            q.pop_front();
        }
        q.push_back(r);
        drop(q);
        self.notify.notify_one();
    }

    fn drain(&self) -> Vec<Received<ControlCommand>> {
        self.queue.lock().drain(..).collect()
    }
}

/// What the ego does when commands stop.
struct Policy {
    spec: ControlPolicy,
    /// The newest command, the simulated time it came at, and its timing (applied_ns 0 until
    /// first applied).
    last: Option<(ControlCommand, u64, ControlTiming)>,
    braking: bool,
    timeouts: u64,
    stale: u64,
}

impl Policy {
    fn new(spec: ControlPolicy) -> Policy {
        Policy { spec, last: None, braking: false, timeouts: 0, stale: 0 }
    }

    fn on_command(&mut self, cmd: &Received<ControlCommand>, now_ns: u64) {
        let stamp = cmd.header.stamp_sim_ns;
        let age_ns = now_ns.saturating_sub(stamp);
        if self.spec.max_age_ms > 0 && stamp != 0 && age_ns > self.spec.max_age_ms * 1_000_000 {
            self.stale += 1;
            if self.stale.is_power_of_two() {
                tracing::warn!(
                    age_ms = age_ns / 1_000_000,
                    max_age_ms = self.spec.max_age_ms,
                    stale = self.stale,
                    from = cmd.source.as_deref().unwrap_or("?"),
                    "vehicle/control answers a state {} ms old: not applied",
                    age_ns / 1_000_000
                );
            }
            return;
        }
        if self.braking {
            tracing::info!("vehicle/control resumed");
            self.braking = false;
        }
        let timing = ControlTiming { command_stamp_pub_ns: cmd.header.stamp_pub_ns, applied_ns: 0 };
        self.last = Some((cmd.msg, now_ns, timing));
    }

    /// The timing of the command in effect, for vehicle/state; None when none is.
    fn timing(&self) -> Option<ControlTiming> {
        match self.last {
            Some((_, _, t)) if !self.braking && t.applied_ns != 0 => Some(t),
            _ => None,
        }
    }

    fn input(&mut self, now_ns: u64) -> super::world::EgoInput {
        use super::world::EgoInput;
        let brake = ControlCommand { brake: self.spec.timeout_brake, ..ControlCommand::NEUTRAL };
        match self.last {
            None => match self.spec.before_first {
                BeforeFirst::Cruise => EgoInput::Cruise,
                BeforeFirst::Brake => EgoInput::Command(brake),
            },
            Some((cmd, at, ref mut timing)) if now_ns.saturating_sub(at) <= self.spec.hold_ms * 1_000_000 => {
                if timing.applied_ns == 0 {
                    timing.applied_ns = crate::msg::wall_clock_ns();
                }
                EgoInput::Command(cmd)
            }
            Some(_) => {
                if !self.braking {
                    tracing::warn!(
                        hold_ms = self.spec.hold_ms,
                        brake = self.spec.timeout_brake,
                        "no vehicle/control for {} ms of simulated time: braking until a command arrives",
                        self.spec.hold_ms
                    );
                    self.braking = true;
                    self.timeouts += 1;
                }
                EgoInput::Command(brake)
            }
        }
    }
}

/// Runs `world` on the bus until its scenario ends or `shutdown` completes.
pub async fn run(
    bus: &Bus,
    mut world: World,
    settings: &SimSettings,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<SimReport, SimError> {
    let stop = Arc::new(AtomicBool::new(false));
    let stop_task = {
        let stop = stop.clone();
        tokio::spawn(async move {
            shutdown.await;
            stop.store(true, Ordering::SeqCst);
        })
    };
    let result = run_loop(bus, &mut world, settings, &stop).await;
    stop_task.abort();
    result
}

async fn run_loop(
    bus: &Bus,
    world: &mut World,
    settings: &SimSettings,
    stop: &AtomicBool,
) -> Result<SimReport, SimError> {
    let speed_pub = bus.publisher(topics::VEHICLE_SPEED).await?;
    let state_pub = bus.publisher(topics::VEHICLE_STATE).await?;
    let clock_pub = bus.publisher(topics::SIM_CLOCK).await?;
    let events_pub = bus.publisher(topics::SIM_EVENTS).await?;
    let objects_pub = bus.publisher(topics::OBJECTS).await?;
    let info_pub = bus.publisher(topics::CAMERA_FRONT_INFO).await?;
    let frames = bus.frame_publisher().await?;
    let inbox = Arc::new(ControlInbox::default());
    let control_sub = {
        let inbox = inbox.clone();
        bus.subscribe_with(topics::VEHICLE_CONTROL, move |r| inbox.push(r)).await?
    };

    let hz = settings.physics_hz;
    let rates = &settings.rates_hz;
    let mode = settings.mode;
    let info = settings.camera_info(frames.encoding());
    let seed = world.seed();
    let noise = world.scenario().noise.clone();
    let (mut renderer, mut look_rng) = Renderer::seeded(&info, noise.camera_stddev, seed);
    let mut scratch = vec![0u8; renderer.frame_len()];
    let mut policy = Policy::new(settings.control.clone());

    info_pub.put(0, &info)?;
    if mode == Mode::Lockstep {
        wait_for_nodes(bus, &settings.lockstep.wait_for, settings.lockstep.start_timeout_ms, stop).await?;
        if !state_pub.wait_for_subscriber(Duration::from_secs(5)).await {
            tracing::warn!("lockstep: nobody subscribes to vehicle/state yet; starting anyway");
        }
    }
    let scenario_name = world.scenario().name.clone();
    tracing::info!(scenario = %scenario_name, seed, ?mode, physics_hz = hz, "scenario start");
    events_pub.put(0, &SimEvent { kind: SimEventKind::ScenarioStart { name: scenario_name.clone(), seed } })?;

    let started = Instant::now();
    let mut window = (started, 0u64);
    let mut rtf = 0.0f32;
    let mut last_progress = started;
    let (mut frames_sent, mut lockstep_timeouts) = (0u64, 0u64);
    let end: Option<End> = loop {
        let k = world.step_count();
        let t_ns = world.time_ns();

        let now = Instant::now();
        let window_s = now.duration_since(window.0).as_secs_f64();
        if window_s >= 1.0 || (k > 0 && window.1 == 0 && window_s > 0.0) {
            rtf = ((t_ns - window.1) as f64 / 1e9 / window_s) as f32;
            if window_s >= 1.0 {
                window = (now, t_ns);
            }
        }
        if now.duration_since(last_progress) >= Duration::from_secs(5) {
            last_progress = now;
            tracing::info!(sim_s = t_ns as f64 / 1e9, rtf, frames = frames_sent, "running");
        }

        let speed_due = due(k, rates.speed, hz);
        let state_due = due(k, rates.state, hz);
        if speed_due {
            speed_pub.put(t_ns, &Speed { speed_mps: world.measured_speed_mps() })?;
        }
        if state_due {
            let state = VehicleState { control_timing: policy.timing(), ..world.ego_state() };
            state_pub.put(t_ns, &state)?;
        }
        if due(k, rates.clock, hz) {
            clock_pub
                .put(t_ns, &SimClock { step: k, real_time_factor: rtf, mode: mode.into(), physics_hz: hz as f64 })?;
        }
        if due(k, rates.camera, hz) {
            let look = renderer.draw_look(noise.brightness, &mut look_rng);
            let mut visibility: Option<Vec<ObjectVisibility>> = None;
            let (w, h) = (info.width, info.height);
            let sent = match frames.encoding() {
                ImageEncoding::Rgb8 => {
                    frames.put_with(t_ns, w, h, ImageEncoding::Rgb8, renderer.frame_len(), |buf| {
                        visibility = Some(renderer.render(world.road(), world.ego(), world.vehicles(), look, buf));
                    })?
                }
                _ => {
                    visibility = Some(renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut scratch));
                    frames.put_rgb(t_ns, w, h, &scratch)?
                }
            };
            frames_sent += sent.is_some() as u64;
            // A frame dropped by the topic's max_rate still gets its ground truth.
            let visibility = match visibility {
                Some(v) => v,
                None => renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut scratch),
            };
            objects_pub.put(t_ns, &ground_truth(world, &visibility))?;
        }

        // The ego's input for the step from k to k + 1.
        if mode == Mode::Lockstep && (speed_due || state_due) {
            let Answers { command, late, strangers } =
                await_answers(&inbox, &settings.lockstep.wait_for, k, settings.lockstep.step_timeout_ms, stop).await;
            if let Some(cmd) = &command {
                policy.on_command(cmd, t_ns);
            }
            if !late.is_empty() && !stop.load(Ordering::SeqCst) {
                lockstep_timeouts += 1;
                let hint = if strangers.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; this step was answered by {}, which lockstep.wait_for does not list (a controller must attach its node name)",
                        strangers.iter().cloned().collect::<Vec<_>>().join(", ")
                    )
                };
                tracing::warn!(
                    step = k,
                    ?late,
                    timeout_ms = settings.lockstep.step_timeout_ms,
                    "lockstep: no answer to this step from {}{hint}",
                    late.join(", ")
                );
                events_pub.put(t_ns, &SimEvent { kind: SimEventKind::ControlTimeout { late: late.clone() } })?;
                if settings.lockstep.on_timeout == OnTimeout::Stop {
                    break Some(End {
                        reason: format!("lockstep timeout at step {k} waiting for {}", late.join(", ")),
                        success: false,
                    });
                }
            }
        } else {
            for r in inbox.drain() {
                policy.on_command(&r, t_ns);
            }
        }
        if stop.load(Ordering::SeqCst) {
            break None;
        }

        let events = world.step(policy.input(t_ns));
        let t_next = world.time_ns();
        for c in events.collisions.iter().filter(|c| c.involves_ego()) {
            let other_id = if c.id_a == EGO_ID { c.id_b } else { c.id_a };
            tracing::warn!(other_id, relative_speed_mps = c.relative_speed_mps, "collision");
            let kind = SimEventKind::Collision { other_id, relative_speed_mps: c.relative_speed_mps };
            events_pub.put(t_next, &SimEvent { kind })?;
        }
        if let Some(end) = events.ended {
            break Some(end);
        }

        match mode {
            Mode::Realtime => {
                let target = started + Duration::from_secs_f64(t_next as f64 / 1e9 / settings.realtime_factor);
                tokio::time::sleep_until(target.into()).await;
            }
            Mode::Fast | Mode::Lockstep => {
                if k % 64 == 0 {
                    tokio::task::yield_now().await;
                }
            }
        }
    };

    let t_end = world.time_ns();
    let (reason, success) = match &end {
        Some(e) => (e.reason.clone(), e.success),
        None => ("stopped".to_string(), world.ego_collisions() == 0),
    };
    tracing::info!(%reason, success, sim_s = t_end as f64 / 1e9, collisions = world.ego_collisions(), "scenario end");
    events_pub.put(t_end, &SimEvent { kind: SimEventKind::ScenarioEnd { reason, success } })?;
    let wall = started.elapsed().as_secs_f64();
    Ok(SimReport {
        scenario: scenario_name,
        seed,
        steps: world.step_count(),
        sim_time_s: t_end as f64 / 1e9,
        wall_time_s: wall,
        real_time_factor: t_end as f64 / 1e9 / wall.max(1e-9),
        frames: frames_sent,
        ego_collisions: world.ego_collisions(),
        traffic_collisions: world.traffic_collisions(),
        lockstep_timeouts,
        control_timeouts: policy.timeouts,
        control_stale: policy.stale,
        control_rejected: control_sub.stats().snapshot().decode_errors,
        end,
    })
}

/// Waits until every awaited node's liveliness token is up.
async fn wait_for_nodes(bus: &Bus, names: &[String], timeout_ms: u64, stop: &AtomicBool) -> Result<(), SimError> {
    let deadline = Instant::now() + Duration::from_millis(timeout_ms);
    let mut logged = false;
    loop {
        let alive = bus.nodes_alive().await?;
        let missing: Vec<&String> = names.iter().filter(|n| !alive.contains(n)).collect();
        if missing.is_empty() {
            return Ok(());
        }
        if !logged {
            tracing::info!(?missing, "lockstep: waiting for the controllers to come up");
            logged = true;
        }
        if Instant::now() >= deadline || stop.load(Ordering::SeqCst) {
            return Err(SimError::Lockstep(format!(
                "{} not up after {} ms (start them, or change lockstep.wait_for in the settings)",
                missing.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", "),
                timeout_ms
            )));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The answers to one lockstep step.
struct Answers {
    /// The command of the first awaited node that answered.
    command: Option<Received<ControlCommand>>,
    /// Awaited nodes that did not answer in time.
    late: Vec<String>,
    /// Senders of answers to this step that lockstep does not wait for ("(unnamed)": no
    /// attachment): usually a controller started under another name.
    strangers: BTreeSet<String>,
}

/// Collects the answers to step `k` until every awaited node answered or the timeout passed.
async fn await_answers(
    inbox: &ControlInbox,
    wait_for: &[String],
    k: u64,
    timeout_ms: u64,
    stop: &AtomicBool,
) -> Answers {
    let deadline = tokio::time::Instant::now() + Duration::from_millis(timeout_ms);
    let mut answers: BTreeMap<&str, Received<ControlCommand>> = BTreeMap::new();
    let mut strangers = BTreeSet::new();
    loop {
        for r in inbox.drain() {
            let from = r.source.as_deref().and_then(|s| wait_for.iter().find(|n| n.as_str() == s));
            match (from, r.msg.answers_step) {
                (Some(name), Some(step)) if step == k => {
                    answers.insert(name.as_str(), r);
                }
                (None, Some(step)) if step == k => {
                    strangers.insert(r.source.clone().unwrap_or_else(|| "(unnamed)".into()));
                }
                (_, step) => {
                    tracing::debug!(source = ?r.source, ?step, waiting_for = k, "vehicle/control ignored in lockstep")
                }
            }
        }
        let now = tokio::time::Instant::now();
        if answers.len() == wait_for.len() || stop.load(Ordering::SeqCst) || now >= deadline {
            break;
        }
        // Wake at least every 100 ms to notice a stop request.
        let _ = tokio::time::timeout_at(deadline.min(now + Duration::from_millis(100)), inbox.notify.notified()).await;
    }
    let late = wait_for.iter().filter(|n| !answers.contains_key(n.as_str())).cloned().collect();
    Answers { command: wait_for.iter().find_map(|n| answers.remove(n.as_str())), late, strangers }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(before_first: BeforeFirst) -> Policy {
        Policy::new(ControlPolicy { hold_ms: 200, timeout_brake: 0.4, max_age_ms: 1000, before_first })
    }

    #[test]
    fn the_last_command_holds_then_the_ego_brakes_until_control_resumes() {
        use crate::sim::world::EgoInput;
        let mut p = policy(BeforeFirst::Cruise);
        assert_eq!(p.input(0), EgoInput::Cruise);
        let go = ControlCommand { throttle: 0.7, ..ControlCommand::NEUTRAL };
        let sent = |stamp_pub_ns| Received {
            header: crate::msg::Header { seq: 0, stamp_sim_ns: 0, stamp_pub_ns },
            msg: go,
            source: None,
        };
        p.on_command(&sent(42), 1_000_000_000);
        assert_eq!(p.timing(), None, "not applied yet");
        assert_eq!(p.input(1_000_000_000), EgoInput::Command(go));
        let timing = p.timing().expect("applied");
        assert_eq!(timing.command_stamp_pub_ns, 42);
        assert!(timing.applied_ns > 0);
        assert_eq!(p.input(1_200_000_000), EgoInput::Command(go), "held for 200 ms");
        assert_eq!(p.timing(), Some(timing), "the first application is kept");
        let brake = EgoInput::Command(ControlCommand { brake: 0.4, ..ControlCommand::NEUTRAL });
        assert_eq!(p.input(1_210_000_000), brake);
        assert_eq!(p.input(5_000_000_000), brake);
        assert_eq!(p.timeouts, 1, "one timeout, however long it lasts");
        assert_eq!(p.timing(), None, "no command in effect while braking");
        p.on_command(&sent(43), 6_000_000_000);
        assert_eq!(p.input(6_010_000_000), EgoInput::Command(go));
        assert_eq!(policy(BeforeFirst::Brake).input(0), brake);
    }

    #[test]
    fn a_command_answering_an_old_state_is_counted_not_applied() {
        use crate::sim::world::EgoInput;
        let mut p = policy(BeforeFirst::Cruise);
        let cmd = |throttle, stamp_sim_ns| Received {
            header: crate::msg::Header { seq: 0, stamp_sim_ns, stamp_pub_ns: 1 },
            msg: ControlCommand { throttle, ..ControlCommand::NEUTRAL },
            source: Some("acc".into()),
        };
        p.on_command(&cmd(0.5, 9_000_000_000), 10_000_000_000);
        assert_eq!(p.input(10_000_000_000), EgoInput::Command(cmd(0.5, 0).msg), "1 s old: still applied");
        // Queued while a link was down, delivered 4 s late: the ego keeps its newer command.
        p.on_command(&cmd(0.9, 6_000_000_000), 10_010_000_000);
        assert_eq!(p.input(10_010_000_000), EgoInput::Command(cmd(0.5, 0).msg));
        assert_eq!(p.stale, 1);
        // Unstamped commands (stamp 0, e.g. a joystick) are taken as fresh.
        p.on_command(&cmd(0.2, 0), 10_020_000_000);
        assert_eq!(p.input(10_020_000_000), EgoInput::Command(cmd(0.2, 0).msg));
        assert_eq!(p.stale, 1);
    }

    #[test]
    fn rates_tick_on_the_right_steps() {
        let steps = |rate| (0..100u64).filter(|k| due(*k, rate, 100)).count();
        assert_eq!(steps(100.0), 100);
        assert_eq!(steps(20.0), 20);
        assert!((0..100u64).filter(|k| due(*k, 20.0, 100)).all(|k| k % 5 == 0));
        assert_eq!(steps(30.0), 30);
    }
}
