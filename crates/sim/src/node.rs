//! The simulator on the bus: publishes the world's topics at their rates, takes each ego's
//! commands from its vehicle/control, and paces the steps (realtime, fast or lockstep).
//!
//! Each controlled vehicle has a port of its own (crates/sim/src/port.rs) publishing in its
//! namespace; one ego's is the run's namespace itself. Each step k publishes what is due at
//! simulation time t_k (speed, state, clock, camera frame with its ground truth) for every
//! ego, then decides each ego's input for the step to k + 1:
//! - realtime / fast: the latest command received, held for `control.hold_ms` of simulated
//!   time, then a brake (the policy logs when it engages and when control resumes);
//! - lockstep, at every step that published speed or state: wait until every node in
//!   `lockstep.wait_for` answered step k in every ego's namespace (`answers_step == k`, the
//!   node named by the sample's attachment), or the step timeout passes (then warn, publish
//!   ControlTimeout naming the late nodes in that namespace, and continue with the policy or
//!   stop). One step waits for all egos at once: the timeout is the step's, not each ego's.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::port::{awaits, on_late, EgoPort, EgoRun, Late};
use super::settings::{Mode, SimSettings};
use super::world::{End, World};
use slipstream_contract::bus::{Bus, NodeClock, StatsSnapshot};
use slipstream_contract::msg::SimEventKind;

pub(crate) use super::error::SimError;

/// How a run went.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SimReport {
    pub scenario: String,
    pub seed: u64,
    pub steps: u64,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    /// Simulated seconds per wall-clock second over the whole run.
    pub real_time_factor: f64,
    pub frames: u64,
    /// Collisions of the controlled vehicles, each ego's counted (with several egos, one
    /// between two of them counts twice here and once in `collisions_between_egos`).
    pub ego_collisions: u64,
    pub traffic_collisions: u64,
    #[serde(default)]
    pub collisions_between_egos: u64,
    /// Each controlled vehicle's side of the run, in the scenario's order; the other figures
    /// are their sums (vehicle/control's input statistics: the first ego's).
    #[serde(default)]
    pub egos: Vec<EgoRun>,
    /// Lockstep steps that timed out waiting for a controller.
    pub lockstep_timeouts: u64,
    /// Times the control policy had to brake for lack of commands.
    pub control_timeouts: u64,
    /// vehicle/control payloads that failed to decode (counted and logged, never applied).
    pub control_rejected: u64,
    /// Commands older than control.max_age_ms of simulated time when they came (not applied).
    pub control_stale: u64,
    /// Commands from another controller than the one followed (not applied).
    #[serde(default)]
    pub control_foreign: u64,
    /// vehicle/control as it reached the simulator: arrived, lost on the way (sequence gaps),
    /// and dropped, delayed or duplicated by injected faults (`--faults`).
    #[serde(default)]
    pub control_input: StatsSnapshot,
    /// None when stopped before the scenario ended.
    pub end: Option<End>,
    /// Where the simulator's wall time went.
    #[serde(default)]
    pub time: SimTime,
}

/// Where the simulator's wall time went, in seconds: what `eval acc` and `up` show of a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SimTime {
    /// Stepping the world: drivers, vehicle model, rapier.
    pub physics_s: f64,
    /// Drawing camera frames (into shared memory when raw) and their ground truth.
    pub render_s: f64,
    /// Publishing everything else (speed, state, clock, objects, events).
    pub publish_s: f64,
    /// Waiting for the controllers' answers (lockstep), or taking the commands that came.
    pub awaiting_s: f64,
    /// Pacing: sleeping to the wall clock (realtime) or yielding (fast, lockstep).
    pub pacing_s: f64,
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

/// Runs `world` on the bus until its scenario ends or `shutdown` completes.
pub async fn run(
    bus: &Bus,
    mut world: World,
    settings: &SimSettings,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<SimReport, SimError> {
    // The publish rates are counted in the settings' steps: the world must step at that rate.
    if world.physics_hz() != settings.physics_hz {
        return Err(SimError::Settings(format!(
            "the world steps at {} Hz but the settings' physics_hz is {} (build the world with World::new(.., settings.physics_hz))",
            world.physics_hz(),
            settings.physics_hz
        )));
    }
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

/// How often a running simulator logs its progress.
const PROGRESS_EVERY: Duration = Duration::from_secs(5);
/// The window the real-time factor is measured over.
const RTF_WINDOW: Duration = Duration::from_secs(1);
/// Fast and lockstep modes yield to the runtime every this many steps.
const YIELD_EVERY_STEPS: u64 = 64;
/// Lockstep: how long to wait for a vehicle/state subscriber before the first step.
const STATE_SUBSCRIBER_WAIT: Duration = Duration::from_secs(5);

/// The real-time factor over the last [`RTF_WINDOW`] of wall time, and the progress log.
struct Pace {
    started: Instant,
    /// Start of the current window: wall time and simulation time.
    window: (Instant, u64),
    rtf: f32,
    last_progress: Instant,
}

impl Pace {
    fn new() -> Pace {
        let now = Instant::now();
        Pace { started: now, window: (now, 0), rtf: 0.0, last_progress: now }
    }

    /// Updates the factor at step `k`, time `t_ns`; logs progress now and then.
    fn measure(&mut self, k: u64, t_ns: u64, frames_sent: u64) {
        let now = Instant::now();
        let window_s = now.duration_since(self.window.0).as_secs_f64();
        if window_s >= RTF_WINDOW.as_secs_f64() || (k > 0 && self.window.1 == 0 && window_s > 0.0) {
            self.rtf = ((t_ns - self.window.1) as f64 / 1e9 / window_s) as f32;
            if window_s >= RTF_WINDOW.as_secs_f64() {
                self.window = (now, t_ns);
            }
        }
        if now.duration_since(self.last_progress) >= PROGRESS_EVERY {
            self.last_progress = now;
            tracing::info!(sim_s = t_ns as f64 / 1e9, rtf = self.rtf, frames = frames_sent, "running");
        }
    }

    /// Waits as the clock mode says before step `k` + 1 at `t_next_ns`.
    async fn wait(&self, mode: Mode, realtime_factor: f64, k: u64, t_next_ns: u64) {
        match mode {
            Mode::Realtime => {
                let target = self.started + Duration::from_secs_f64(t_next_ns as f64 / 1e9 / realtime_factor);
                tokio::time::sleep_until(target.into()).await;
            }
            Mode::Fast | Mode::Lockstep => {
                if k.is_multiple_of(YIELD_EVERY_STEPS) {
                    tokio::task::yield_now().await;
                }
            }
        }
    }
}

/// The simulator's ports, one per controlled vehicle, and what the run counts.
struct Node<'a> {
    settings: &'a SimSettings,
    ports: Vec<EgoPort>,
    node_clock: Arc<NodeClock>,
    /// Steps at which any awaited node of any ego was late.
    lockstep_timeouts: u64,
    time: SimTime,
}

impl<'a> Node<'a> {
    async fn open(bus: &Bus, world: &World, settings: &'a SimSettings) -> Result<Node<'a>, SimError> {
        let mut ports = Vec::with_capacity(world.ego_count());
        for (k, spec) in world.scenario().egos().iter().enumerate() {
            let scoped = bus.scoped(spec.namespace.as_deref().unwrap_or(""))?;
            ports.push(EgoPort::open(scoped, world, k, settings).await?);
        }
        let node_clock = bus.clock().clone();
        Ok(Node { settings, ports, node_clock, lockstep_timeouts: 0, time: SimTime::default() })
    }

    /// The latched messages, the lockstep start (every ego's nodes up), the scenario's start.
    async fn start(&self, world: &World, stop: &AtomicBool) -> Result<(), SimError> {
        for port in &self.ports {
            port.latch(world)?;
        }
        let lockstep = &self.settings.lockstep;
        if self.settings.mode == Mode::Lockstep {
            for port in &self.ports {
                wait_for_nodes(port.bus(), &lockstep.wait_for, lockstep.start_timeout_ms, stop).await?;
                if !port.state_heard(STATE_SUBSCRIBER_WAIT).await {
                    let ns = port.bus().topics().namespace().to_string();
                    tracing::warn!(namespace = %ns, "lockstep: nobody subscribes to vehicle/state yet; starting anyway");
                }
            }
        }
        let (name, seed) = (world.scenario().name.clone(), world.seed());
        tracing::info!(scenario = %name, seed, egos = self.ports.len(), mode = ?self.settings.mode,
            physics_hz = self.settings.physics_hz, "scenario start");
        for port in &self.ports {
            port.event(0, SimEventKind::ScenarioStart { name: name.clone(), seed })?;
        }
        Ok(())
    }

    /// Publishes what is due at step `k` for every ego; whether the step awaits answers.
    fn publish(&mut self, world: &mut World, k: u64, t_ns: u64, rtf: f32) -> Result<bool, SimError> {
        let mut wait = false;
        for port in &mut self.ports {
            let published = port.publish(world, k, t_ns, rtf, self.settings, &mut self.time.render_s)?;
            wait |= awaits(self.settings, &published);
        }
        Ok(wait)
    }

    /// Takes the commands for the step from `k` to `k` + 1: in lockstep (when `wait`) every
    /// ego's awaited nodes' answers within one step timeout, else whatever arrived. Some(end)
    /// when a lockstep timeout stops the run.
    async fn take_commands(
        &mut self,
        k: u64,
        t_ns: u64,
        wait: bool,
        stop: &AtomicBool,
    ) -> Result<Option<End>, SimError> {
        // The simulator's own time releases the commands injected faults held back.
        self.node_clock.advance(t_ns);
        if !wait {
            for port in &mut self.ports {
                port.take_arrived(t_ns);
            }
            return Ok(None);
        }
        let deadline = Instant::now() + Duration::from_millis(self.settings.lockstep.step_timeout_ms);
        let mut late = Vec::new();
        for port in &mut self.ports {
            let left = deadline.saturating_duration_since(Instant::now()).as_millis() as u64;
            let missing = port.take_answers(k, t_ns, self.settings, left, stop).await?;
            // Names are qualified only when a node was late: nothing is formatted on a step
            // every ego answered.
            late.extend(missing.into_iter().map(|l| match port.ego_namespace() {
                Some(ns) => Late { name: format!("{ns}/{}", l.name), why: l.why },
                None => l,
            }));
        }
        self.lockstep_timeouts += !late.is_empty() as u64;
        Ok(on_late(self.settings, k, &late))
    }

    fn frames_sent(&self) -> u64 {
        self.ports.iter().map(|p| p.frames_sent).sum()
    }

    /// The scenario's end on every ego's sim/events, and the run's report.
    fn finish(&self, world: &World, end: Option<End>, pace: &Pace) -> Result<SimReport, SimError> {
        let t_end = world.time_ns();
        let egos: Vec<EgoRun> = self.ports.iter().map(|p| p.run(world)).collect();
        let collisions: u64 = egos.iter().map(|e| e.collisions).sum();
        let (reason, success) = match &end {
            Some(e) => (e.reason.clone(), e.success),
            None => ("stopped".to_string(), collisions == 0),
        };
        tracing::info!(%reason, success, sim_s = t_end as f64 / 1e9, collisions, "scenario end");
        for port in &self.ports {
            port.event(t_end, SimEventKind::ScenarioEnd { reason: reason.clone(), success })?;
        }
        let wall = pace.started.elapsed().as_secs_f64();
        let sum = |f: fn(&EgoRun) -> u64| egos.iter().map(f).sum::<u64>();
        Ok(SimReport {
            scenario: world.scenario().name.clone(),
            seed: world.seed(),
            steps: world.step_count(),
            sim_time_s: t_end as f64 / 1e9,
            wall_time_s: wall,
            real_time_factor: t_end as f64 / 1e9 / wall.max(1e-9),
            frames: self.frames_sent(),
            ego_collisions: collisions,
            traffic_collisions: world.traffic_collisions(),
            collisions_between_egos: world.collisions_between_egos(),
            lockstep_timeouts: self.lockstep_timeouts,
            control_timeouts: sum(|e| e.control_timeouts),
            control_stale: sum(|e| e.control_stale),
            control_rejected: sum(|e| e.control_rejected),
            control_input: self.ports[0].control_input(),
            control_foreign: sum(|e| e.control_foreign),
            egos,
            end,
            time: self.time,
        })
    }
}

async fn run_loop(
    bus: &Bus,
    world: &mut World,
    settings: &SimSettings,
    stop: &AtomicBool,
) -> Result<SimReport, SimError> {
    // Realtime keeps the configured QoS; fast and lockstep runs publish every message (the
    // step waits rather than a subscriber missing one).
    if settings.mode != Mode::Realtime {
        bus.keep_every_message();
    }
    let mut node = Node::open(bus, world, settings).await?;
    bus.announce().await?;
    node.start(world, stop).await?;
    let mut pace = Pace::new();
    let mut lap = Instant::now();
    // The wall time since the last lap, added to one of the run's shares.
    let mut split = |share: &mut f64| {
        let now = Instant::now();
        *share += now.duration_since(lap).as_secs_f64();
        lap = now;
    };
    let end: Option<End> = loop {
        let (k, t_ns) = (world.step_count(), world.time_ns());
        pace.measure(k, t_ns, node.frames_sent());
        let rendered = node.time.render_s;
        let wait = node.publish(world, k, t_ns, pace.rtf)?;
        // publish() added its frames' time to render_s: the rest of it is publishing.
        split(&mut node.time.publish_s);
        node.time.publish_s -= node.time.render_s - rendered;
        let ended = node.take_commands(k, t_ns, wait, stop).await?;
        split(&mut node.time.awaiting_s);
        if let Some(end) = ended {
            break Some(end);
        }
        if stop.load(Ordering::SeqCst) {
            break None;
        }
        let inputs: Vec<_> = node.ports.iter_mut().map(|p| p.policy.input(t_ns)).collect();
        let events = world.step_all(&inputs);
        split(&mut node.time.physics_s);
        for port in &node.ports {
            port.publish_collisions(&events, world.time_ns())?;
        }
        if let Some(end) = events.ended {
            break Some(end);
        }
        pace.wait(settings.mode, settings.realtime_factor, k, world.time_ns()).await;
        split(&mut node.time.pacing_s);
    };
    node.finish(world, end, &pace)
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
                "{} not up after {} ms (start them, or change lockstep.wait_for in the settings; a node is up once it declares its liveliness token nodes/<name>, Bus::announce in Rust)",
                missing.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", "),
                timeout_ms
            )));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}
