//! One controlled vehicle's side of the simulator ([`EgoPort`]): its topics, published in its
//! namespace (a single ego's in the run's own), its cameras, its ground truth, its control
//! input and its timeout policy. Every namespace is a whole loop as one ego's nodes see it,
//! so a detector and a controller run for one ego of many exactly as for the only one.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

use super::control_in::{await_answers, ControlInbox, Policy};
use super::error::SimError;
use super::ground_truth::ground_truth_of;
use super::render::{seen_by_either, ObjectVisibility, Renderer};
use super::rng::SimRng;
use super::settings::{Mode, OnTimeout, SimSettings};
use super::world::{End, StepEvents, World};
use slipstream_contract::bus::{Bus, CallbackSubscriber, Following, FramePublisher, Publisher};
use slipstream_contract::msg::{
    due, CameraFrame, CameraInfo, EgoInfo, GroundTruthObjects, ImageEncoding, RoadSpec, SimClock, SimEvent,
    SimEventKind, Speed, VehicleState,
};
use slipstream_contract::topics::{self, Topic, TopicDef};

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
    /// Ego `k`'s camera: the first ego's is seeded with the run's seed (as a single ego's
    /// always was), the others' with seeds of their own.
    async fn open(
        bus: &Bus,
        world: &World,
        k: usize,
        frames: TopicDef<CameraFrame>,
        info: TopicDef<CameraInfo>,
        describe: impl FnOnce(ImageEncoding) -> Option<CameraInfo>,
    ) -> Result<SimCamera, SimError> {
        let frames = bus.frame_publisher(frames).await?;
        let camera_info = describe(frames.encoding()).expect("the camera opened is on");
        let noise = &world.scenario().noise;
        let seed = world.seed() ^ ((k as u64) << 48);
        let (renderer, look_rng) = match frames.publisher().topic() {
            Topic::CameraFront => Renderer::seeded(&camera_info, noise.camera_stddev, seed),
            _ => Renderer::seeded_narrow(&camera_info, noise.camera_stddev, seed),
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
    fn publish(&mut self, world: &World, k: usize, t_ns: u64) -> Result<(Vec<ObjectVisibility>, bool), SimError> {
        let ego = world.ego_at(k);
        let look = self.renderer.draw_look(self.brightness, &mut self.look_rng);
        let mut visibility: Option<Vec<ObjectVisibility>> = None;
        let (w, h) = (self.info.width, self.info.height);
        let renderer = &mut self.renderer;
        let sent = match self.frames.encoding() {
            ImageEncoding::Rgb8 => {
                self.frames.put_with(t_ns, w, h, ImageEncoding::Rgb8, renderer.frame_len(), |buf| {
                    visibility = Some(renderer.render(world.road(), ego, world.vehicles(), look, buf));
                })?
            }
            _ => {
                visibility = Some(renderer.render(world.road(), ego, world.vehicles(), look, &mut self.scratch));
                self.frames.put_rgb(t_ns, w, h, &self.scratch)?
            }
        };
        let visibility = match visibility {
            Some(v) => v,
            None => renderer.render(world.road(), ego, world.vehicles(), look, &mut self.scratch),
        };
        Ok((visibility, sent.is_some()))
    }
}

/// Which of the ego's topics step k published (lockstep answers those steps).
pub(crate) struct Published {
    pub speed: bool,
    pub state: bool,
}

/// One ego's publishers, cameras and control input, on the bus scoped to its namespace.
pub(crate) struct EgoPort {
    /// Which ego (the scenario's `egos[k]`).
    k: usize,
    /// Its namespace under the run's; None: the run's own (one ego).
    namespace: Option<String>,
    bus: Bus,
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
    pub policy: Policy,
    pub frames_sent: u64,
    /// Steps at which a node this ego waits for did not answer in time.
    pub lockstep_timeouts: u64,
}

/// What one ego's side of a run counted, in the run's report.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EgoRun {
    /// Its namespace under the run's (empty: the run's own).
    pub namespace: String,
    pub collisions: u64,
    pub lockstep_timeouts: u64,
    pub control_timeouts: u64,
    pub control_stale: u64,
    pub control_rejected: u64,
    pub control_foreign: u64,
    pub frames: u64,
}

impl EgoPort {
    /// Ego `k`'s side, on `bus` scoped to its namespace.
    pub(crate) async fn open(bus: Bus, world: &World, k: usize, settings: &SimSettings) -> Result<EgoPort, SimError> {
        let camera = SimCamera::open(&bus, world, k, topics::CAMERA_FRONT, topics::CAMERA_FRONT_INFO, |e| {
            Some(settings.camera_info(e))
        })
        .await?;
        let narrow = match settings.narrow_camera.enabled {
            true => Some(
                SimCamera::open(&bus, world, k, topics::CAMERA_NARROW, topics::CAMERA_NARROW_INFO, |e| {
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
        Ok(EgoPort {
            k,
            namespace: world.scenario().egos()[k].namespace.clone(),
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
            control_from: Following::new("vehicle/control"),
            policy: Policy::new(settings.control.clone()),
            frames_sent: 0,
            lockstep_timeouts: 0,
            bus,
        })
    }

    /// The bus in this ego's namespace.
    pub(crate) fn bus(&self) -> &Bus {
        &self.bus
    }

    /// Its namespace under the run's; None: the run's own.
    pub(crate) fn ego_namespace(&self) -> Option<&str> {
        self.namespace.as_deref()
    }

    /// The latched messages: camera info, road, the ego's vehicle.
    pub(crate) fn latch(&self, world: &World) -> Result<(), SimError> {
        for camera in std::iter::once(&self.camera).chain(&self.narrow) {
            camera.info_pub.put(0, &camera.info)?;
        }
        self.road_pub.put(0, world.road().spec())?;
        self.ego_pub.put(0, &ego_info(world, self.k))?;
        Ok(())
    }

    /// Whether anybody subscribes to this ego's vehicle/state within `wait`.
    pub(crate) async fn state_heard(&self, wait: std::time::Duration) -> bool {
        self.state.wait_for_subscriber(wait).await
    }

    /// An event on this ego's sim/events.
    pub(crate) fn event(&self, t_ns: u64, kind: SimEventKind) -> Result<(), SimError> {
        self.events.put(t_ns, &SimEvent { kind })?;
        Ok(())
    }

    /// Publishes what is due at step `k` (time `t_ns`) for this ego: speed, state, clock,
    /// camera frame with its ground truth. `render_s` gets the frames' wall time.
    pub(crate) fn publish(
        &mut self,
        world: &mut World,
        step: u64,
        t_ns: u64,
        rtf: f32,
        settings: &SimSettings,
        render_s: &mut f64,
    ) -> Result<Published, SimError> {
        let (hz, rates) = (settings.physics_hz, &settings.rates_hz);
        let published = Published { speed: due(step, rates.speed, hz), state: due(step, rates.state, hz) };
        if published.speed {
            self.speed.put(t_ns, &Speed { speed_mps: world.measured_speed_of(self.k) })?;
        }
        if published.state {
            let state = VehicleState { control_timing: self.policy.timing(), ..world.ego_state_of(self.k) };
            self.state.put(t_ns, &state)?;
        }
        if due(step, rates.clock, hz) {
            let mode = settings.mode.into();
            self.clock.put(t_ns, &SimClock { step, real_time_factor: rtf, mode, physics_hz: hz as f64 })?;
        }
        if due(step, rates.camera, hz) {
            let started = Instant::now();
            self.publish_frame(world, t_ns)?;
            *render_s += started.elapsed().as_secs_f64();
        }
        Ok(published)
    }

    /// Renders the frames (into shared memory when raw), publishes them and the ground truth.
    /// The narrow camera's frame goes first: a detector using both has it when the front
    /// camera's frame of the same step arrives.
    fn publish_frame(&mut self, world: &World, t_ns: u64) -> Result<(), SimError> {
        let narrow = match self.narrow.as_mut() {
            Some(camera) => Some(camera.publish(world, self.k, t_ns)?.0),
            None => None,
        };
        let (visibility, sent) = self.camera.publish(world, self.k, t_ns)?;
        self.frames_sent += sent as u64;
        let visibility = match narrow {
            Some(narrow) => seen_by_either(visibility, &narrow),
            None => visibility,
        };
        self.objects.put(t_ns, &ground_truth_of(world, self.k, &visibility))?;
        Ok(())
    }

    /// Takes whatever commands arrived (realtime, fast, or a lockstep step that published
    /// neither speed nor state): one controller at a time, the first that named itself
    /// (lockstep goes by lockstep.wait_for instead).
    pub(crate) fn take_arrived(&mut self, t_ns: u64) {
        for r in self.inbox.drain() {
            if self.control_from.accept(r.source.as_deref(), Instant::now()) {
                self.policy.on_command(&r, t_ns);
            }
        }
    }

    /// Lockstep: the awaited nodes' answers to step `k` until `timeout_ms` passes; the names of
    /// those that did not answer (the step's timeout is then counted and announced here).
    pub(crate) async fn take_answers(
        &mut self,
        step: u64,
        t_ns: u64,
        settings: &SimSettings,
        timeout_ms: u64,
        stop: &AtomicBool,
    ) -> Result<Vec<Late>, SimError> {
        let wait_for = &settings.lockstep.wait_for;
        let arrivals = self.control_sub.arrivals();
        let answers = await_answers(&self.inbox, arrivals, self.faulted, wait_for, step, t_ns, timeout_ms, stop).await;
        for cmd in answers.earlier.iter().chain(&answers.command) {
            self.policy.on_command(cmd, t_ns);
        }
        if answers.late.is_empty() || stop.load(std::sync::atomic::Ordering::SeqCst) {
            return Ok(Vec::new());
        }
        self.lockstep_timeouts += 1;
        let undecodable = self.control_sub.stats().snapshot().decode_errors;
        let late: Vec<Late> = answers
            .late
            .iter()
            .map(|name| {
                let why = answers.why_late(name, step).or_else(|| {
                    (undecodable > 0).then(|| format!("{undecodable} vehicle/control payloads did not decode so far"))
                });
                Late { name: name.clone(), why }
            })
            .collect();
        let said: Vec<String> = late.iter().map(Late::to_string).collect();
        let ns = self.bus.topics().namespace().to_string();
        tracing::warn!(step, namespace = %ns, timeout_ms = settings.lockstep.step_timeout_ms,
            "lockstep: no answer to this step from {}", said.join(", "));
        self.event(t_ns, SimEventKind::ControlTimeout { late: answers.late.clone() })?;
        Ok(late)
    }

    /// Publishes this ego's collisions of the step that ended at `t_ns`.
    pub(crate) fn publish_collisions(&self, events: &StepEvents, t_ns: u64) -> Result<(), SimError> {
        let me = self.k as u32;
        for c in events.collisions.iter().filter(|c| c.involves(me)) {
            let other_id = c.other_than(me);
            tracing::warn!(other_id, relative_speed_mps = c.relative_speed_mps, ego = self.k, "collision");
            self.event(t_ns, SimEventKind::Collision { other_id, relative_speed_mps: c.relative_speed_mps })?;
        }
        Ok(())
    }

    /// What this ego's side counted.
    pub(crate) fn run(&self, world: &World) -> EgoRun {
        let input = self.control_sub.stats().snapshot();
        EgoRun {
            namespace: self.namespace.clone().unwrap_or_default(),
            collisions: world.collisions_of(self.k),
            lockstep_timeouts: self.lockstep_timeouts,
            control_timeouts: self.policy.timeouts,
            control_stale: self.policy.stale,
            control_rejected: input.decode_errors,
            control_foreign: self.control_from.rejected(),
            frames: self.frames_sent,
        }
    }

    /// vehicle/control as it reached this ego.
    pub(crate) fn control_input(&self) -> slipstream_contract::bus::StatsSnapshot {
        self.control_sub.stats().snapshot()
    }
}

/// A node lockstep waited for in vain, and why as far as the step saw (the step its commands
/// answered instead, a stranger answering in its place, payloads that did not decode).
pub(crate) struct Late {
    pub(crate) name: String,
    pub(crate) why: Option<String>,
}

impl std::fmt::Display for Late {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.why {
            Some(why) => write!(f, "{} ({why})", self.name),
            None => write!(f, "{}", self.name),
        }
    }
}

/// Lockstep's policy for a step with late nodes: Some(end) when it stops the run, naming each
/// late node and why.
pub(crate) fn on_late(settings: &SimSettings, step: u64, late: &[Late]) -> Option<End> {
    (settings.lockstep.on_timeout == OnTimeout::Stop && !late.is_empty()).then(|| End {
        reason: format!(
            "lockstep timeout at step {step} waiting for {}",
            late.iter().map(Late::to_string).collect::<Vec<_>>().join(", ")
        ),
        success: false,
    })
}

/// Whether step `k` waits for answers: lockstep, at a step that published speed or state.
pub(crate) fn awaits(settings: &SimSettings, published: &Published) -> bool {
    settings.mode == Mode::Lockstep && (published.speed || published.state)
}

/// Ego `k`'s vehicle and its driver's settings, as the scenario gives them.
fn ego_info(world: &World, k: usize) -> EgoInfo {
    let (ego, spec) = (world.ego_at(k), &world.scenario().egos()[k]);
    ego.params.ego_info(ego.class, spec.controller_set_speed_mps(), spec.time_gap_s)
}
