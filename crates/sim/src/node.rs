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
use super::render::{seen_by_either, ObjectVisibility, Renderer};
use super::rng::SimRng;
use super::settings::{BeforeFirst, ControlPolicy, Mode, OnTimeout, SimSettings};
use super::world::{End, StepEvents, World, EGO_ID};
use slipstream_contract::bus::{
    Arrivals, Bus, BusError, CallbackSubscriber, Following, FramePublisher, NodeClock, Publisher, Received,
    StatsSnapshot,
};
use slipstream_contract::msg::{
    due, CameraFrame, CameraInfo, ControlCommand, ControlTiming, EgoInfo, GroundTruthObjects, ImageEncoding, RoadSpec,
    SimClock, SimEvent, SimEventKind, Speed, VehicleState,
};
use slipstream_contract::topics::{self, Topic, TopicDef};

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("lockstep: {0}")]
    Lockstep(String),
    #[error("camera: {0}")]
    Camera(String),
    #[error("settings: {0}")]
    Settings(String),
}

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
                    timing.applied_ns = slipstream_contract::msg::wall_clock_ns();
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

/// The simulator's publishers, its camera and its control input: what one step uses.
struct Node<'a> {
    settings: &'a SimSettings,
    speed: Publisher<Speed>,
    state: Publisher<VehicleState>,
    clock: Publisher<SimClock>,
    events: Publisher<SimEvent>,
    objects: Publisher<GroundTruthObjects>,
    /// The road (latched): where lanes go, for controllers.
    road_pub: Publisher<RoadSpec>,
    ego_pub: Publisher<EgoInfo>,
    camera: SimCamera,
    /// The long-range camera, when on.
    narrow: Option<SimCamera>,
    inbox: Arc<ControlInbox>,
    control_sub: CallbackSubscriber,
    /// Faults are injected into vehicle/control here (`--faults`).
    faulted: bool,
    control_from: Following,
    node_clock: Arc<NodeClock>,
    policy: Policy,
    frames_sent: u64,
    lockstep_timeouts: u64,
    time: SimTime,
}

/// One camera of the simulator: its renderer, its frames and its info (latched).
struct SimCamera {
    frames: FramePublisher,
    info_pub: Publisher<CameraInfo>,
    info: CameraInfo,
    renderer: Renderer,
    look_rng: SimRng,
    brightness: f64,
    /// Where JPEG frames and frames dropped by a rate limit are rendered.
    scratch: Vec<u8>,
}

impl SimCamera {
    async fn open(
        bus: &Bus,
        world: &World,
        frames: TopicDef<CameraFrame>,
        info: TopicDef<CameraInfo>,
        describe: impl FnOnce(ImageEncoding) -> Option<CameraInfo>,
    ) -> Result<SimCamera, SimError> {
        let frames = bus.frame_publisher(frames).await?;
        let camera_info = describe(frames.encoding()).expect("the camera opened is on");
        let noise = &world.scenario().noise;
        let (renderer, look_rng) = match frames.publisher().topic() {
            Topic::CameraFront => Renderer::seeded(&camera_info, noise.camera_stddev, world.seed()),
            _ => Renderer::seeded_narrow(&camera_info, noise.camera_stddev, world.seed()),
        };
        Ok(SimCamera {
            frames,
            info_pub: bus.publisher(info).await?,
            scratch: vec![0u8; renderer.frame_len()],
            info: camera_info,
            renderer,
            look_rng,
            brightness: noise.brightness,
        })
    }

    /// Renders and publishes a frame; every vehicle's visibility in it, and whether it went
    /// out (a topic's max_rate can drop it: its visibility is still measured).
    fn publish(&mut self, world: &World, t_ns: u64) -> Result<(Vec<ObjectVisibility>, bool), SimError> {
        let look = self.renderer.draw_look(self.brightness, &mut self.look_rng);
        let mut visibility: Option<Vec<ObjectVisibility>> = None;
        let (w, h) = (self.info.width, self.info.height);
        let renderer = &mut self.renderer;
        let sent = match self.frames.encoding() {
            ImageEncoding::Rgb8 => {
                self.frames.put_with(t_ns, w, h, ImageEncoding::Rgb8, renderer.frame_len(), |buf| {
                    visibility = Some(renderer.render(world.road(), world.ego(), world.vehicles(), look, buf));
                })?
            }
            _ => {
                visibility =
                    Some(renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut self.scratch));
                self.frames.put_rgb(t_ns, w, h, &self.scratch)?
            }
        };
        let visibility = match visibility {
            Some(v) => v,
            None => renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut self.scratch),
        };
        Ok((visibility, sent.is_some()))
    }
}

/// Which of the ego's topics step k published (lockstep answers those steps).
struct Published {
    speed: bool,
    state: bool,
}

impl<'a> Node<'a> {
    async fn open(bus: &Bus, world: &World, settings: &'a SimSettings) -> Result<Node<'a>, SimError> {
        let camera = SimCamera::open(bus, world, topics::CAMERA_FRONT, topics::CAMERA_FRONT_INFO, |e| {
            Some(settings.camera_info(e))
        })
        .await?;
        let narrow = match settings.narrow_camera.enabled {
            true => Some(
                SimCamera::open(bus, world, topics::CAMERA_NARROW, topics::CAMERA_NARROW_INFO, |e| {
                    settings.narrow_camera_info(e)
                })
                .await?,
            ),
            false => None,
        };
        let inbox = Arc::new(ControlInbox::default());
        let control_sub = {
            let inbox = inbox.clone();
            bus.subscribe_with(topics::VEHICLE_CONTROL, move |r| inbox.push(r)).await?
        };
        Ok(Node {
            settings,
            speed: bus.publisher(topics::VEHICLE_SPEED).await?,
            state: bus.publisher(topics::VEHICLE_STATE).await?,
            clock: bus.publisher(topics::SIM_CLOCK).await?,
            events: bus.publisher(topics::SIM_EVENTS).await?,
            objects: bus.publisher(topics::OBJECTS).await?,
            road_pub: bus.publisher(topics::SIM_ROAD).await?,
            ego_pub: bus.publisher(topics::SIM_EGO).await?,
            camera,
            narrow,
            inbox,
            control_sub,
            faulted: bus.faults().is_some_and(|p| p.at(topics::VEHICLE_CONTROL.topic, bus.node()).is_some()),
            node_clock: bus.clock().clone(),
            control_from: Following::new("vehicle/control"),
            policy: Policy::new(settings.control.clone()),
            frames_sent: 0,
            lockstep_timeouts: 0,
            time: SimTime::default(),
        })
    }

    /// The camera info and the road (latched), the lockstep start (its nodes up), the
    /// scenario's start.
    async fn start(&self, bus: &Bus, world: &World, stop: &AtomicBool) -> Result<(), SimError> {
        for camera in std::iter::once(&self.camera).chain(&self.narrow) {
            camera.info_pub.put(0, &camera.info)?;
        }
        self.road_pub.put(0, world.road().spec())?;
        self.ego_pub.put(0, &ego_info(world))?;
        let lockstep = &self.settings.lockstep;
        if self.settings.mode == Mode::Lockstep {
            wait_for_nodes(bus, &lockstep.wait_for, lockstep.start_timeout_ms, stop).await?;
            if !self.state.wait_for_subscriber(STATE_SUBSCRIBER_WAIT).await {
                tracing::warn!("lockstep: nobody subscribes to vehicle/state yet; starting anyway");
            }
        }
        let (name, seed) = (world.scenario().name.clone(), world.seed());
        tracing::info!(scenario = %name, seed, mode = ?self.settings.mode, physics_hz = self.settings.physics_hz, "scenario start");
        self.events.put(0, &SimEvent { kind: SimEventKind::ScenarioStart { name, seed } })?;
        Ok(())
    }

    /// Publishes what is due at step `k` (time `t_ns`): speed, state, clock, camera frame
    /// with its ground truth.
    fn publish(&mut self, world: &mut World, k: u64, t_ns: u64, rtf: f32) -> Result<Published, SimError> {
        let (hz, rates) = (self.settings.physics_hz, &self.settings.rates_hz);
        let published = Published { speed: due(k, rates.speed, hz), state: due(k, rates.state, hz) };
        if published.speed {
            self.speed.put(t_ns, &Speed { speed_mps: world.measured_speed_mps() })?;
        }
        if published.state {
            let state = VehicleState { control_timing: self.policy.timing(), ..world.ego_state() };
            self.state.put(t_ns, &state)?;
        }
        if due(k, rates.clock, hz) {
            let mode = self.settings.mode.into();
            self.clock.put(t_ns, &SimClock { step: k, real_time_factor: rtf, mode, physics_hz: hz as f64 })?;
        }
        if due(k, rates.camera, hz) {
            let started = Instant::now();
            self.publish_frame(world, t_ns)?;
            self.time.render_s += started.elapsed().as_secs_f64();
        }
        Ok(published)
    }

    /// Renders the frames (into shared memory when raw), publishes them and the ground truth.
    /// The narrow camera's frame goes first: a detector using both has it when the front
    /// camera's frame of the same step arrives.
    fn publish_frame(&mut self, world: &World, t_ns: u64) -> Result<(), SimError> {
        let narrow = match self.narrow.as_mut() {
            Some(camera) => Some(camera.publish(world, t_ns)?.0),
            None => None,
        };
        let (visibility, sent) = self.camera.publish(world, t_ns)?;
        self.frames_sent += sent as u64;
        let visibility = match narrow {
            Some(narrow) => seen_by_either(visibility, &narrow),
            None => visibility,
        };
        self.objects.put(t_ns, &ground_truth(world, &visibility))?;
        Ok(())
    }

    /// Takes the commands for the step from `k` to `k` + 1: in lockstep (on steps that
    /// published speed or state) the awaited nodes' answers, else whatever arrived. Some(end)
    /// when a lockstep timeout stops the run.
    async fn take_commands(
        &mut self,
        k: u64,
        t_ns: u64,
        published: &Published,
        stop: &AtomicBool,
    ) -> Result<Option<End>, SimError> {
        let lockstep = &self.settings.lockstep;
        // The simulator's own time releases the commands injected faults held back.
        self.node_clock.advance(t_ns);
        if self.settings.mode != Mode::Lockstep || !(published.speed || published.state) {
            for r in self.inbox.drain() {
                // One controller at a time: the first that named itself (lockstep goes by
                // lockstep.wait_for instead).
                if self.control_from.accept(r.source.as_deref(), Instant::now()) {
                    self.policy.on_command(&r, t_ns);
                }
            }
            return Ok(None);
        }
        let faulted = self.faulted;
        let arrivals = self.control_sub.arrivals();
        let Answers { command, earlier, late, strangers } =
            await_answers(&self.inbox, arrivals, faulted, &lockstep.wait_for, k, t_ns, lockstep.step_timeout_ms, stop)
                .await;
        for cmd in &earlier {
            self.policy.on_command(cmd, t_ns);
        }
        if let Some(cmd) = &command {
            self.policy.on_command(cmd, t_ns);
        }
        if late.is_empty() || stop.load(Ordering::SeqCst) {
            return Ok(None);
        }
        self.lockstep_timeouts += 1;
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
            timeout_ms = lockstep.step_timeout_ms,
            "lockstep: no answer to this step from {}{hint}",
            late.join(", ")
        );
        self.events.put(t_ns, &SimEvent { kind: SimEventKind::ControlTimeout { late: late.clone() } })?;
        Ok((lockstep.on_timeout == OnTimeout::Stop).then(|| End {
            reason: format!("lockstep timeout at step {k} waiting for {}", late.join(", ")),
            success: false,
        }))
    }

    /// Publishes the ego's collisions of the step that ended at `t_ns`.
    fn publish_collisions(&self, events: &StepEvents, t_ns: u64) -> Result<(), SimError> {
        for c in events.collisions.iter().filter(|c| c.involves_ego()) {
            let other_id = if c.id_a == EGO_ID { c.id_b } else { c.id_a };
            tracing::warn!(other_id, relative_speed_mps = c.relative_speed_mps, "collision");
            let kind = SimEventKind::Collision { other_id, relative_speed_mps: c.relative_speed_mps };
            self.events.put(t_ns, &SimEvent { kind })?;
        }
        Ok(())
    }

    /// The scenario's end on sim/events, and the run's report.
    fn finish(&self, world: &World, end: Option<End>, pace: &Pace) -> Result<SimReport, SimError> {
        let t_end = world.time_ns();
        let (reason, success) = match &end {
            Some(e) => (e.reason.clone(), e.success),
            None => ("stopped".to_string(), world.ego_collisions() == 0),
        };
        tracing::info!(%reason, success, sim_s = t_end as f64 / 1e9, collisions = world.ego_collisions(), "scenario end");
        self.events.put(t_end, &SimEvent { kind: SimEventKind::ScenarioEnd { reason, success } })?;
        let wall = pace.started.elapsed().as_secs_f64();
        Ok(SimReport {
            scenario: world.scenario().name.clone(),
            seed: world.seed(),
            steps: world.step_count(),
            sim_time_s: t_end as f64 / 1e9,
            wall_time_s: wall,
            real_time_factor: t_end as f64 / 1e9 / wall.max(1e-9),
            frames: self.frames_sent,
            ego_collisions: world.ego_collisions(),
            traffic_collisions: world.traffic_collisions(),
            lockstep_timeouts: self.lockstep_timeouts,
            control_timeouts: self.policy.timeouts,
            control_stale: self.policy.stale,
            control_rejected: self.control_sub.stats().snapshot().decode_errors,
            control_input: self.control_sub.stats().snapshot(),
            control_foreign: self.control_from.rejected(),
            end,
            time: self.time,
        })
    }
}

/// The ego's vehicle and its driver's settings, as the scenario gives them.
fn ego_info(world: &World) -> EgoInfo {
    let (ego, spec) = (world.ego(), &world.scenario().ego);
    let p = &ego.params;
    EgoInfo {
        class: ego.class,
        size_m: p.size_m,
        rear_overhang_m: p.rear_overhang_m,
        wheelbase_m: p.wheelbase_m,
        mass_kg: p.mass_kg,
        max_power_w: p.max_power_w,
        max_drive_force_n: p.max_drive_force_n,
        max_brake_decel_mps2: p.max_brake_decel_mps2,
        drag_area_m2: p.drag_area_m2,
        rolling_coeff: p.rolling_coeff,
        actuator_lag_s: p.actuator_lag_s,
        set_speed_mps: spec.controller_set_speed_mps(),
        time_gap_s: spec.time_gap_s,
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
    node.start(bus, world, stop).await?;
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
        pace.measure(k, t_ns, node.frames_sent);
        let rendered = node.time.render_s;
        let published = node.publish(world, k, t_ns, pace.rtf)?;
        // publish() added its frames' time to render_s: the rest of it is publishing.
        split(&mut node.time.publish_s);
        node.time.publish_s -= node.time.render_s - rendered;
        let ended = node.take_commands(k, t_ns, &published, stop).await?;
        split(&mut node.time.awaiting_s);
        if let Some(end) = ended {
            break Some(end);
        }
        if stop.load(Ordering::SeqCst) {
            break None;
        }
        let events = world.step(node.policy.input(t_ns));
        split(&mut node.time.physics_s);
        node.publish_collisions(&events, world.time_ns())?;
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

/// The answers to one lockstep step.
struct Answers {
    /// The command of the first awaited node that answered.
    command: Option<Received<ControlCommand>>,
    /// With injected faults: answers to earlier steps that faults held back until now (applied
    /// before `command`, in their order).
    earlier: Vec<Received<ControlCommand>>,
    /// Awaited nodes that did not answer in time.
    late: Vec<String>,
    /// Senders of answers to this step that lockstep does not wait for ("(unnamed)": no
    /// attachment): usually a controller started under another name.
    strangers: BTreeSet<String>,
}

/// Collects the answers to step `k` (stamped `t_ns`) until every awaited node answered or the
/// timeout passed. With injected faults (`faulted`) an answer counts once it arrived, even if
/// the faults dropped or held it: the step goes on with what was delivered.
#[allow(clippy::too_many_arguments)]
async fn await_answers(
    inbox: &ControlInbox,
    arrivals: &Arrivals,
    faulted: bool,
    wait_for: &[String],
    k: u64,
    t_ns: u64,
    timeout_ms: u64,
    stop: &AtomicBool,
) -> Answers {
    let deadline = tokio::time::Instant::now() + Duration::from_millis(timeout_ms);
    let mut answers: BTreeMap<&str, Received<ControlCommand>> = BTreeMap::new();
    let mut earlier = Vec::new();
    let mut strangers = BTreeSet::new();
    let arrived = |n: &String| faulted && arrivals.since_from(n, t_ns);
    loop {
        // Arrivals first: an answer seen arrived was handed on before, so the drain gets it.
        let all_arrived = wait_for.iter().all(arrived);
        for r in inbox.drain() {
            let from = r.source.as_deref().and_then(|s| wait_for.iter().find(|n| n.as_str() == s));
            match (from, r.msg.answers_step) {
                (Some(name), Some(step)) if step == k => {
                    answers.insert(name.as_str(), r);
                }
                (Some(_), Some(step)) if faulted && step < k => earlier.push(r),
                (None, Some(step)) if step == k => {
                    strangers.insert(r.source.clone().unwrap_or_else(|| "(unnamed)".into()));
                }
                (_, step) => {
                    tracing::debug!(source = ?r.source, ?step, waiting_for = k, "vehicle/control ignored in lockstep")
                }
            }
        }
        let now = tokio::time::Instant::now();
        let answered = |n: &String| answers.contains_key(n.as_str()) || arrived(n);
        if all_arrived || wait_for.iter().all(answered) || stop.load(Ordering::SeqCst) || now >= deadline {
            break;
        }
        // Wake at least every 100 ms to notice a stop request.
        let wake = deadline.min(now + Duration::from_millis(100)) - now;
        tokio::select! {
            _ = tokio::time::timeout(wake, inbox.notify.notified()) => {}
            _ = arrivals.wait(wake, || wait_for.iter().all(arrived)) => {}
        }
    }
    let answered = |n: &&String| answers.contains_key(n.as_str()) || arrived(n);
    let late = wait_for.iter().filter(|n| !answered(n)).cloned().collect();
    Answers { command: wait_for.iter().find_map(|n| answers.remove(n.as_str())), earlier, late, strangers }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(before_first: BeforeFirst) -> Policy {
        Policy::new(ControlPolicy { hold_ms: 200, timeout_brake: 0.4, max_age_ms: 1000, before_first })
    }

    #[test]
    fn the_last_command_holds_then_the_ego_brakes_until_control_resumes() {
        use crate::world::EgoInput;
        let mut p = policy(BeforeFirst::Cruise);
        assert_eq!(p.input(0), EgoInput::Cruise);
        let go = ControlCommand { throttle: 0.7, ..ControlCommand::NEUTRAL };
        let sent = |stamp_pub_ns| Received {
            header: slipstream_contract::msg::Header { seq: 0, stamp_sim_ns: 0, stamp_pub_ns },
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
        use crate::world::EgoInput;
        let mut p = policy(BeforeFirst::Cruise);
        let cmd = |throttle, stamp_sim_ns| Received {
            header: slipstream_contract::msg::Header { seq: 0, stamp_sim_ns, stamp_pub_ns: 1 },
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
}
